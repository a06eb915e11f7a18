//! Hierarchical view-frustum culling: the baseline every paper compares against.
//!
//! Preprocessing builds a [`Bvh`] per node of the scene DAG: over the triangles of each mesh
//! with more than [`FrustumOptions::mesh_leaf_size`] triangles, and over the instances of each
//! group with more than a few. A frame walks the DAG from the root without flattening it: at
//! each node instance it forms the frustum in that node's space (planes of
//! `clip_from_object`), descends the node's hierarchy, skips subtrees outside, stops testing
//! inside subtrees wholly inside, and hands the surviving triangles to the rasterizer as
//! index lists (whole meshes when entirely inside, so their vertices are shared).
//!
//! Cost: O(visited nodes + triangles in the frustum). It removes nothing that is in the frustum
//! but hidden; that is the occlusion culling renderers' job.

use std::sync::Arc;
use std::time::Instant;

use occult_core::{compose, Affine3A, Containment, ItemId, NodeId, NodeKind, Scene, View};
use occult_raster::{Draw, DrawTriangles, Frame, Rasterizer};
use occult_spatial::Bvh;

use crate::{check_frame, AlgorithmInfo, FrameStats, ParamDoc, Phase, RenderError, RenderOptions, Renderer, Result};

/// Tunables of [`FrustumCulling`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrustumOptions {
    /// Triangles per BVH leaf of a mesh (≥ 1): smaller culls finer but visits more nodes.
    pub mesh_leaf_size: usize,
    /// Instances per BVH leaf of a group (≥ 1).
    pub group_leaf_size: usize,
}

impl Default for FrustumOptions {
    fn default() -> Self {
        Self {
            mesh_leaf_size: 256,
            group_leaf_size: 4,
        }
    }
}

/// Registry entry of [`FrustumCulling`].
pub static INFO: AlgorithmInfo = AlgorithmInfo {
    name: "frustum",
    summary: "hierarchical view-frustum culling over a BVH per mesh and per group; the baseline",
    params: &[
        ParamDoc {
            key: "leaf",
            default: "256",
            help: "triangles per BVH leaf of a mesh (>= 1)",
        },
        ParamDoc {
            key: "group_leaf",
            default: "4",
            help: "instances per BVH leaf of a group (>= 1)",
        },
    ],
    conservative: true,
    build: |scene, options, params| {
        let defaults = FrustumOptions::default();
        let fo = FrustumOptions {
            mesh_leaf_size: params.get("leaf", defaults.mesh_leaf_size)?,
            group_leaf_size: params.get("group_leaf", defaults.group_leaf_size)?,
        };
        Ok(Box::new(FrustumCulling::with_options(scene, options, &fo)?))
    },
};

/// The frustum-culling renderer.
pub struct FrustumCulling {
    scene: Arc<Scene>,
    raster: Rasterizer,
    /// Per node: its hierarchy (None when small enough to test as one box).
    hierarchies: Vec<Option<Bvh>>,
}

impl FrustumCulling {
    /// Builds the per-node hierarchies of `scene` with default [`FrustumOptions`].
    ///
    /// # Errors
    /// Raster configuration errors.
    pub fn new(scene: Arc<Scene>, options: &RenderOptions) -> Result<Self> {
        Self::with_options(scene, options, &FrustumOptions::default())
    }

    /// Builds the per-node hierarchies of `scene`.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a zero leaf size; raster configuration errors.
    pub fn with_options(scene: Arc<Scene>, options: &RenderOptions, fo: &FrustumOptions) -> Result<Self> {
        if fo.mesh_leaf_size == 0 || fo.group_leaf_size == 0 {
            return Err(RenderError::BadParameter(
                "frustum: leaf sizes must be at least 1".into(),
            ));
        }
        let raster = Rasterizer::new(options.raster.clone())?;
        let hierarchies = raster.install(|| {
            use rayon::prelude::*;
            scene
                .nodes()
                .par_iter()
                .map(|node| match node.kind() {
                    NodeKind::Mesh(m) if m.triangle_count() > fo.mesh_leaf_size => {
                        let boxes: Vec<_> = (0..m.triangle_count())
                            .map(|t| occult_core::Aabb::from_points(m.triangle_positions(t)))
                            .collect();
                        Some(Bvh::build(&boxes, fo.mesh_leaf_size))
                    }
                    NodeKind::Group(g) if g.len() > fo.group_leaf_size => {
                        let boxes: Vec<_> = g
                            .iter()
                            .map(|i| scene.node(i.child).bounds().transformed(&i.parent_from_child))
                            .collect();
                        Some(Bvh::build(&boxes, fo.group_leaf_size))
                    }
                    _ => None,
                })
                .collect()
        });
        Ok(Self {
            scene,
            raster,
            hierarchies,
        })
    }
}

/// Per-frame traversal state.
struct Walk<'a> {
    scene: &'a Scene,
    hierarchies: &'a [Option<Bvh>],
    view: &'a View,
    draws: Vec<Draw<'a>>,
    stats: FrameStats,
}

impl<'a> Walk<'a> {
    /// Visits node `id` placed by `world_from_node`; `inside` when an ancestor was wholly inside.
    fn node(&mut self, id: NodeId, world_from_node: &Affine3A, first_item: ItemId, inside: bool) {
        let node = self.scene.node(id);
        let frustum = self.view.frustum(world_from_node);
        let test = |stats: &mut FrameStats, b: &occult_core::Aabb| -> Containment {
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
        };
        self.stats.nodes_visited += 1;
        let inside = inside || {
            match test(&mut self.stats, &node.bounds()) {
                Containment::Outside => return,
                c => c == Containment::Inside,
            }
        };
        let clip_from_object = self.view.clip_from_object(world_from_node);
        match node.kind() {
            NodeKind::Mesh(mesh) => {
                if mesh.triangle_count() == 0 {
                    return;
                }
                let bvh = match (&self.hierarchies[id.index()], inside) {
                    (Some(bvh), false) => bvh,
                    _ => {
                        self.draws.push(Draw {
                            mesh,
                            triangles: DrawTriangles::All,
                            clip_from_object,
                            first_item,
                        });
                        return;
                    }
                };
                let first_draw = self.draws.len();
                let mut kept = 0usize;
                let mut stack = vec![(0u32, false)];
                while let Some((n, inside)) = stack.pop() {
                    let bn = &bvh.nodes()[n as usize];
                    self.stats.nodes_visited += 1;
                    let inside = inside
                        || match test(&mut self.stats, &bn.bounds) {
                            Containment::Outside => continue,
                            c => c == Containment::Inside,
                        };
                    if inside || bn.is_leaf() {
                        let list = &bvh.primitive_indices()[bn.range()];
                        kept += list.len();
                        self.draws.push(Draw {
                            mesh,
                            triangles: DrawTriangles::List(list),
                            clip_from_object,
                            first_item,
                        });
                    } else {
                        stack.push((bn.second_child, false));
                        stack.push((n + 1, false));
                    }
                }
                // Index lists transform each corner once per triangle; a whole mesh shares its
                // vertices. When most of the mesh survived, drawing it whole is cheaper (the
                // rasterizer's outcode test drops the rest at a few ns each).
                if kept * 2 > mesh.triangle_count() {
                    self.draws.truncate(first_draw);
                    self.draws.push(Draw {
                        mesh,
                        triangles: DrawTriangles::All,
                        clip_from_object,
                        first_item,
                    });
                }
            }
            NodeKind::Group(instances) => {
                let visit = |w: &mut Self, i: usize, inside: bool| {
                    let inst = &instances[i];
                    let world_from_child = compose(world_from_node, &inst.parent_from_child);
                    w.node(inst.child, &world_from_child, first_item + node.item_offset(i), inside);
                };
                match &self.hierarchies[id.index()] {
                    Some(bvh) if !inside => {
                        let mut stack = vec![0u32];
                        while let Some(n) = stack.pop() {
                            let bn = &bvh.nodes()[n as usize];
                            self.stats.nodes_visited += 1;
                            let c = test(&mut self.stats, &bn.bounds);
                            if c == Containment::Outside {
                                continue;
                            }
                            if c == Containment::Inside || bn.is_leaf() {
                                for &i in &bvh.primitive_indices()[bn.range()] {
                                    visit(self, i as usize, c == Containment::Inside);
                                }
                            } else {
                                stack.push(bn.second_child);
                                stack.push(n + 1);
                            }
                        }
                    }
                    _ => {
                        for i in 0..instances.len() {
                            visit(self, i, inside);
                        }
                    }
                }
            }
        }
    }
}

impl Renderer for FrustumCulling {
    fn name(&self) -> &'static str {
        "frustum"
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        check_frame(view, frame)?;
        let start = Instant::now();
        self.raster.clear(frame);
        let clear = start.elapsed();
        let t = Instant::now();
        let mut walk = Walk {
            scene: &self.scene,
            hierarchies: &self.hierarchies,
            view,
            draws: Vec::new(),
            stats: FrameStats::default(),
        };
        walk.node(self.scene.root(), &Affine3A::IDENTITY, 0, false);
        let Walk { draws, mut stats, .. } = walk;
        stats.phases.add(Phase::Clear, clear);
        stats.phases.add(Phase::Cull, t.elapsed());
        crate::rasterize(&mut self.raster, view, frame, &draws, &mut stats);
        stats.total = start.elapsed();
        Ok(stats)
    }

    fn memory_bytes(&self) -> usize {
        self.hierarchies.iter().flatten().map(Bvh::memory_bytes).sum()
    }
}
