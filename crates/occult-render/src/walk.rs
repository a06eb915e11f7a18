//! The one walk over the scene DAG that every renderer uses.
//!
//! `occult-core`'s rule is that transforms are composed walking down from the root
//! ([`occult_core::compose`]), so that every renderer gets bit-identical matrices, hence frames,
//! for the same triangle instance. This module is where that walk lives, with what comes with
//! it in every renderer:
//! - [`Placed`]: a node occurrence's `world_from_node` and first item id, and
//!   [`Placed::child`], the only place a child's placement and item ids are derived;
//! - [`SceneWalk`]: the frame's counts ([`FrameStats::nodes_visited`], `boxes_tested`,
//!   `boxes_culled`), the counted frustum test ([`SceneWalk::test`]: an empty box is outside),
//!   and the cap on the triangles one frame may draw ([`MAX_FRAME_TRIANGLES`], reported as
//!   [`RenderError::TooManyInView`] by [`SceneWalk::finish`]);
//! - [`Visitor`]: a renderer's own part, static dispatch: [`Visitor::enter`] forms the frustum in
//!   the node's space, applies the node test the visitor asks for ([`NodeTest`]: an ancestor
//!   wholly inside keeps its descendants inside, untested) and hands the occurrence
//!   ([`NodeAt`]) to [`Visitor::visit`], which descends the renderer's own hierarchy and calls
//!   [`Visitor::enter`] for the instances it keeps;
//! - [`cull_bvh`]: the frustum-culled descent of a [`Bvh`], shared by the renderers that use one.
//!
//! Cost: per node occurrence one frustum (six planes from `clip_from_object`) and one box test;
//! no allocation, no dynamic dispatch.
//!
//! ```
//! use std::sync::Arc;
//! use occult_core::{Camera, Mesh, NodeKind, Scene, View, Vec3};
//! use occult_render::walk::{NodeAt, SceneWalk, Visitor};
//!
//! /// Counts the triangles of the mesh instances whose box is not outside the view.
//! struct Count<'s> {
//!     walk: SceneWalk<'s>,
//!     triangles: usize,
//! }
//! impl<'s> Visitor<'s> for Count<'s> {
//!     fn walk(&mut self) -> &mut SceneWalk<'s> {
//!         &mut self.walk
//!     }
//!     fn visit(&mut self, at: &NodeAt<'s>) {
//!         match at.node.kind() {
//!             NodeKind::Mesh(mesh) => self.triangles += mesh.triangle_count(),
//!             NodeKind::Group(instances) => {
//!                 for i in 0..instances.len() {
//!                     self.enter(at.child(i), at.inside);
//!                 }
//!             }
//!         }
//!     }
//! }
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])?;
//! let scene = Scene::from_mesh("tri", mesh)?;
//! let view = View::new(Camera::look_at(Vec3::new(0.3, 0.3, 2.0), Vec3::new(0.3, 0.3, 0.0)), 32, 32)?;
//! let mut count = Count { walk: SceneWalk::new(&scene, &view), triangles: 0 };
//! count.run();
//! assert_eq!(count.triangles, 1);
//! let stats = count.walk.finish("count")?;
//! assert_eq!((stats.nodes_visited, stats.boxes_tested, stats.boxes_culled), (1, 1, 0));
//! # Ok(())
//! # }
//! ```

use occult_core::{compose, Aabb, Affine3A, Containment, Frustum, ItemId, Node, NodeId, Scene, View};
use occult_spatial::{Bvh, BvhNode};

use crate::{FrameStats, RenderError, Result};

/// The most triangles (counted as the walk meets them) one frame may draw: past it a frame is
/// refused with [`RenderError::TooManyInView`] before anything is allocated for them.
pub const MAX_FRAME_TRIANGLES: u64 = crate::zbuffer::MAX_BRUTE_FORCE_ITEMS;

/// A node occurrence: the node, its placement composed walking down from the root, and the
/// item id of its first triangle instance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placed {
    /// The node.
    pub id: NodeId,
    /// Its placement: the product of the instance transforms from the root down.
    pub world_from_node: Affine3A,
    /// Item id of its first triangle instance.
    pub first_item: ItemId,
}

impl Placed {
    /// The scene's root, at the identity and item 0.
    pub fn root(scene: &Scene) -> Self {
        Self {
            id: scene.root(),
            world_from_node: Affine3A::IDENTITY,
            first_item: 0,
        }
    }

    /// Instance `instance_index` of this occurrence, whose node is the group `node`.
    ///
    /// # Panics
    /// When `instance_index` is not an instance of `node` (a mesh has none).
    #[inline]
    pub fn child_of(&self, node: &Node, instance_index: usize) -> Self {
        let inst = &node.instances()[instance_index];
        Self {
            id: inst.child,
            world_from_node: compose(&self.world_from_node, &inst.parent_from_child),
            first_item: self.first_item + node.item_offset(instance_index),
        }
    }

    /// Instance `instance_index` of this occurrence (its node looked up in `scene`).
    ///
    /// # Panics
    /// As [`Placed::child_of`].
    #[inline]
    pub fn child(&self, scene: &Scene, instance_index: usize) -> Self {
        self.child_of(scene.node(self.id), instance_index)
    }
}

/// A node occurrence the walk entered, as [`Visitor::visit`] receives it.
#[derive(Clone, Copy, Debug)]
pub struct NodeAt<'s> {
    /// Where it is.
    pub place: Placed,
    /// The node itself.
    pub node: &'s Node,
    /// The view frustum in the node's space ([`View::frustum`] of `world_from_node`).
    pub frustum: Frustum,
    /// True when the node's box lies wholly inside the frustum, or an ancestor's did: nothing
    /// below needs a frustum test.
    pub inside: bool,
}

impl NodeAt<'_> {
    /// Instance `instance_index` of this (group) occurrence.
    ///
    /// # Panics
    /// As [`Placed::child_of`].
    #[inline]
    pub fn child(&self, instance_index: usize) -> Placed {
        self.place.child_of(self.node, instance_index)
    }
}

/// What [`Visitor::enter`] does with a node's own box before visiting it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NodeTest {
    /// Counts the node visited and tests its box with [`SceneWalk::test`] (counted; skipped
    /// when `inside`); a node outside is not visited.
    Counted,
    /// Counts the node visited and tests its box without counting the test (the renderer
    /// counts other tests as its box tests); a node outside is not visited; `inside` is this
    /// box's own result.
    Uncounted,
    /// No test, no count: the visitor tests what it needs (its own hierarchy's root).
    None,
}

/// One frame's walk: the scene and view, the counts, and the triangle cap.
pub struct SceneWalk<'s> {
    scene: &'s Scene,
    view: &'s View,
    /// The frame's statistics so far (the walk's counts and whatever the visitor adds).
    pub stats: FrameStats,
    triangles: u64,
    too_many: bool,
}

impl<'s> SceneWalk<'s> {
    /// A walk of `scene` seen by `view`, with zero counts.
    pub fn new(scene: &'s Scene, view: &'s View) -> Self {
        Self {
            scene,
            view,
            stats: FrameStats::default(),
            triangles: 0,
            too_many: false,
        }
    }

    /// The scene walked.
    #[inline]
    pub fn scene(&self) -> &'s Scene {
        self.scene
    }

    /// The view.
    #[inline]
    pub fn view(&self) -> &'s View {
        self.view
    }

    /// The counted frustum test: classifies `b` against `frustum`, an empty box being outside,
    /// and counts it in `boxes_tested` (and `boxes_culled` when outside).
    #[inline]
    pub fn test(&mut self, frustum: &Frustum, b: &Aabb) -> Containment {
        test_box(&mut self.stats, frustum, b)
    }

    /// Meets `count` more triangles that the frame will draw; past [`MAX_FRAME_TRIANGLES`] the
    /// walk stops ([`SceneWalk::stopped`]) and [`SceneWalk::finish`] fails.
    #[inline]
    pub fn meet_triangles(&mut self, count: u64) {
        self.triangles += count;
        self.too_many |= self.triangles > MAX_FRAME_TRIANGLES;
    }

    /// Triangles met so far.
    pub fn triangles_met(&self) -> u64 {
        self.triangles
    }

    /// True once more triangles than a frame can draw were met: [`Visitor::enter`] enters
    /// nothing more.
    #[inline]
    pub fn stopped(&self) -> bool {
        self.too_many
    }

    /// The frame's statistics.
    ///
    /// # Errors
    /// [`RenderError::TooManyInView`] naming `renderer` when the walk stopped.
    pub fn finish(self, renderer: &'static str) -> Result<FrameStats> {
        if self.too_many {
            return Err(RenderError::TooManyInView {
                renderer,
                limit: MAX_FRAME_TRIANGLES,
            });
        }
        Ok(self.stats)
    }
}

/// The counted frustum test on any statistics: `boxes_tested` + 1, and `boxes_culled` + 1 when
/// `b` is outside `frustum` or empty.
#[inline]
pub fn test_box(stats: &mut FrameStats, frustum: &Frustum, b: &Aabb) -> Containment {
    stats.boxes_tested += 1;
    let c = if b.is_empty() {
        Containment::Outside
    } else {
        frustum.classify_aabb(b)
    };
    if c == Containment::Outside {
        stats.boxes_culled += 1;
    }
    c
}

/// A renderer's part of the walk: its own hierarchy below each node occurrence.
///
/// Implementors hold their [`SceneWalk`] and return it from [`Visitor::walk`]; the provided
/// [`Visitor::run`] and [`Visitor::enter`] do the rest.
pub trait Visitor<'s>: Sized {
    /// What [`Visitor::enter`] does with a node's own box.
    const NODE_TEST: NodeTest = NodeTest::Counted;

    /// The walk's state.
    fn walk(&mut self) -> &mut SceneWalk<'s>;

    /// Visits an occurrence that passed the node test: descends the renderer's hierarchy,
    /// gathers or draws, and enters the instances it keeps (their placement from
    /// [`NodeAt::child`]).
    fn visit(&mut self, at: &NodeAt<'s>);

    /// Walks the scene from its root.
    fn run(&mut self) {
        let root = Placed::root(self.walk().scene);
        self.enter(root, false);
    }

    /// Enters the occurrence `place` (`inside`: an ancestor lies wholly inside the frustum):
    /// forms its frustum, applies [`Visitor::NODE_TEST`] and visits it. Nothing once the
    /// walk [`stopped`](SceneWalk::stopped).
    fn enter(&mut self, place: Placed, inside: bool) {
        let walk = self.walk();
        if walk.too_many {
            return;
        }
        let node = walk.scene.node(place.id);
        let frustum = walk.view.frustum(&place.world_from_node);
        let inside = match Self::NODE_TEST {
            NodeTest::Counted => {
                walk.stats.nodes_visited += 1;
                inside
                    || match walk.test(&frustum, &node.bounds()) {
                        Containment::Outside => return,
                        c => c == Containment::Inside,
                    }
            }
            NodeTest::Uncounted => {
                walk.stats.nodes_visited += 1;
                let b = node.bounds();
                match if b.is_empty() {
                    Containment::Outside
                } else {
                    frustum.classify_aabb(&b)
                } {
                    Containment::Outside => return,
                    c => c == Containment::Inside,
                }
            }
            NodeTest::None => inside,
        };
        self.visit(&NodeAt {
            place,
            node,
            frustum,
            inside,
        });
    }
}

/// Where [`cull_bvh`] counts: plain statistics, or a visitor's walk.
pub trait Counts {
    /// The statistics counted into.
    fn counts(&mut self) -> &mut FrameStats;
}

impl Counts for FrameStats {
    fn counts(&mut self) -> &mut FrameStats {
        self
    }
}

/// The frustum-culled descent of `bvh`, depth first, first child first: each node reached is
/// counted visited and, unless an ancestor was wholly inside, tested ([`test_box`]); a node
/// outside is dropped; `visit(cx, node_index, node, inside)` is called for the others and,
/// for an inner node, returns whether to descend into its children (which inherit `inside`).
/// Nothing when `bvh` has no node.
#[inline]
pub fn cull_bvh<C: Counts>(
    cx: &mut C,
    bvh: &Bvh,
    frustum: &Frustum,
    mut visit: impl FnMut(&mut C, u32, &BvhNode, bool) -> bool,
) {
    if bvh.nodes().is_empty() {
        return;
    }
    let mut stack = vec![(0u32, false)];
    while let Some((n, inside)) = stack.pop() {
        let node = &bvh.nodes()[n as usize];
        let stats = cx.counts();
        stats.nodes_visited += 1;
        let inside = inside
            || match test_box(stats, frustum, &node.bounds) {
                Containment::Outside => continue,
                c => c == Containment::Inside,
            };
        if visit(cx, n, node, inside) && !node.is_leaf() {
            stack.push((node.second_child, inside));
            stack.push((n + 1, inside));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::{Camera, NodeKind, Vec3};

    /// Counts the mesh instances entered and the triangles met.
    struct Meshes<'s> {
        walk: SceneWalk<'s>,
        entered: Vec<Placed>,
    }

    impl<'s> Visitor<'s> for Meshes<'s> {
        fn walk(&mut self) -> &mut SceneWalk<'s> {
            &mut self.walk
        }
        fn visit(&mut self, at: &NodeAt<'s>) {
            match at.node.kind() {
                NodeKind::Mesh(m) => {
                    self.entered.push(at.place);
                    self.walk.meet_triangles(m.triangle_count() as u64);
                }
                NodeKind::Group(instances) => {
                    for i in 0..instances.len() {
                        self.enter(at.child(i), at.inside);
                    }
                }
            }
        }
    }

    fn run<'s>(scene: &'s Scene, view: &'s View) -> Meshes<'s> {
        let mut m = Meshes {
            walk: SceneWalk::new(scene, view),
            entered: Vec::new(),
        };
        m.run();
        m
    }

    fn view_from(eye: Vec3, target: Vec3) -> View {
        View::new(Camera::look_at(eye, target), 64, 48).expect("a 64x48 view")
    }

    #[test]
    fn children_are_placed_as_compose_places_them_with_their_item_offsets() {
        let scene = crate::tests::cubes_on_ground([-9.0, 9.0, -20.0, 2.0], [Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0)]);
        let root = Placed::root(&scene);
        let node = scene.node(root.id);
        for (i, inst) in node.instances().iter().enumerate() {
            let child = root.child(&scene, i);
            assert_eq!(child.id, inst.child);
            assert_eq!(
                child.world_from_node,
                compose(&Affine3A::IDENTITY, &inst.parent_from_child)
            );
            assert_eq!(child.first_item, node.item_offset(i));
        }
    }

    #[test]
    fn a_scene_in_view_is_entered_whole_and_tested_once_when_inside() {
        let scene = crate::tests::cubes_on_ground([-1.0, 1.0, -1.0, 1.0], [Vec3::ZERO]);
        let view = view_from(Vec3::new(0.0, 2.0, 12.0), Vec3::ZERO);
        let m = run(&scene, &view);
        assert_eq!(m.entered.len(), 2, "ground and cube");
        assert_eq!(m.entered[0].first_item, 0);
        assert_eq!(m.entered[1].first_item, 2, "after the ground's 2 triangles");
        // The root lies wholly inside: its children are neither tested nor culled.
        let stats = m
            .walk
            .finish("test")
            .expect("a box and a quad are not too many to draw");
        assert_eq!((stats.nodes_visited, stats.boxes_tested, stats.boxes_culled), (3, 1, 0));
    }

    #[test]
    fn a_scene_behind_the_camera_is_culled_at_the_root() {
        let scene = crate::tests::cubes_on_ground([-1.0, 1.0, -1.0, 1.0], [Vec3::ZERO]);
        let view = view_from(Vec3::new(0.0, 0.0, 5.0), Vec3::new(0.0, 0.0, 10.0));
        let m = run(&scene, &view);
        assert!(m.entered.is_empty());
        let stats = m.walk.finish("test").expect("nothing in view is not too many to draw");
        assert_eq!((stats.nodes_visited, stats.boxes_tested, stats.boxes_culled), (1, 1, 1));
    }

    #[test]
    fn an_empty_box_is_outside_and_counted() {
        let view = view_from(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO);
        let mut stats = FrameStats::default();
        let frustum = view.frustum(&Affine3A::IDENTITY);
        assert_eq!(test_box(&mut stats, &frustum, &Aabb::EMPTY), Containment::Outside);
        assert_eq!((stats.boxes_tested, stats.boxes_culled), (1, 1));
    }

    #[test]
    fn past_the_triangle_cap_the_walk_stops_and_fails() {
        let scene = crate::tests::cubes_on_ground([-1.0, 1.0, -1.0, 1.0], [Vec3::ZERO]);
        let view = view_from(Vec3::new(0.0, 2.0, 12.0), Vec3::ZERO);
        let mut m = Meshes {
            walk: SceneWalk::new(&scene, &view),
            entered: Vec::new(),
        };
        m.walk.meet_triangles(MAX_FRAME_TRIANGLES);
        assert!(!m.walk.stopped(), "the cap itself is allowed");
        m.run();
        assert!(m.walk.stopped());
        assert_eq!(m.entered.len(), 1, "nothing entered after the ground passed the cap");
        assert!(matches!(
            m.walk.finish("test"),
            Err(RenderError::TooManyInView {
                renderer: "test",
                limit: MAX_FRAME_TRIANGLES
            })
        ));
    }

    #[test]
    fn cull_bvh_visits_nothing_of_an_empty_hierarchy_and_counts_every_node_reached() {
        let view = view_from(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO);
        let frustum = view.frustum(&Affine3A::IDENTITY);
        let mut stats = FrameStats::default();
        cull_bvh(&mut stats, &Bvh::build(&[], 1), &frustum, |_, _, _, _| {
            panic!("no node")
        });
        assert_eq!(stats, FrameStats::default());
        // Two boxes in view, one behind the camera: leaves of one box each.
        let boxes = [
            Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5)),
            Aabb::new(Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.5, 0.5, 0.5)),
            Aabb::new(Vec3::new(0.0, 0.0, 20.0), Vec3::new(0.5, 0.5, 21.0)),
        ];
        let bvh = Bvh::build(&boxes, 1);
        let mut leaves = Vec::new();
        cull_bvh(&mut stats, &bvh, &frustum, |_, _, node, _| {
            if node.is_leaf() {
                leaves.extend_from_slice(&bvh.primitive_indices()[node.range()]);
            }
            true
        });
        leaves.sort_unstable();
        assert_eq!(leaves, [0, 1]);
        assert!(stats.boxes_tested <= stats.nodes_visited);
        assert!(stats.boxes_culled >= 1, "the box behind the camera");
    }
}
