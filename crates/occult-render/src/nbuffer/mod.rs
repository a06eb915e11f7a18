//! N-buffer occlusion culling (`nbuffer`).
//!
//! # References
//! Décoret, *N-Buffers for efficient depth map query*, 2005 (`papers/n-buffers-decoret-2005.txt`):
//! - §3.1: occluders are drawn, an N-buffer is built from the depth buffer (§2,
//!   [`occult_raster::NBuffer`], min variant = farthest depth in our reversed-Z), every
//!   object's screen box and nearest depth is tested with four lookups (Fig. 3 cover), and
//!   the survivors not drawn yet are drawn. The paper's occluders are the objects visible in
//!   the previous frame \[BWPP04\] (`occluders=visible`); see *Parts* for the default.
//! - §3.2: particle culling, [`particles`].
//! - §4.2 / Table 2: the same test over a hierarchy of bounding volumes (`hierarchy=bvh`) or
//!   over every object (`hierarchy=flat`): testing a node costs the same four lookups as
//!   testing one object, so a culled node saves all its objects' tests.
//!
//! # Objects
//! An object is a mesh instance of the scene DAG, or, for a mesh of more than `leaf`
//! triangles, a leaf of a median-split BVH over its triangles (so one terrain mesh is many
//! objects). The default `leaf` (256) splits a building or a machine into parts: a part's
//! box is tighter than the whole's (more are culled), and a near occluder is a wall rather
//! than a whole building. Transforms are composed from the root exactly as `frustum` and `zbuffer` do and
//! each object keeps its instance's first item id, so frames are bit-identical to `zbuffer`'s
//! (DESIGN invariant 2): every object that can put a fragment in the frame is drawn.
//! Objects are flattened at build time (refused above [`MAX_OBJECTS`]); the hierarchy is a
//! BVH over their world boxes.
//!
//! Why not the crate's scene walk ([`crate::walk::Visitor`]): §3.1 marks *objects* visible
//! from one frame to the next, so objects are numbered once, at build time, by
//! [`Scene::for_each_mesh_instance`] (occult-core's walk, composing transforms from the root
//! as every renderer does); a frame then walks the flat BVH over them in world space, with the
//! walk's counted frustum test ([`crate::walk::test_box`]) and BVH descent
//! ([`crate::walk::cull_bvh`]).
//!
//! # Parts
//! - **Near occluders** (`occluders=near`, default; `both` adds last frame's visible set):
//!   the objects in the frustum whose screen boxes cover at least `near_area` of the screen,
//!   largest first, at most `near_max` (a box reaching the near plane counts as the whole
//!   screen). Found by a frustum walk of the hierarchy that skips subtrees whose own screen
//!   box is smaller than `near_area`. They occlude from the first frame and after any jump of
//!   the camera, where the visible set of the last frame occludes nothing.
//! - **Coarse N-buffer** (`scale`): the depth map is first reduced to the farthest depth of
//!   each `scale × scale` block, the N-buffer is built over that, and a tested rectangle is
//!   widened to the blocks holding its pixels: conservative (a block's sample is at most
//!   every pixel's depth), a build `scale²` times smaller for a slightly coarser test.
//! - **Second pass** (`passes=2`): the survivors are sorted by nearest depth; the nearer
//!   half is drawn, the N-buffer rebuilt over the new depth, and the farther half tested
//!   again; skipped for [`SECOND_PASS_SKIP`] frames after a frame where the rebuild cost more
//!   than the drawing it saved.
//! - **Payoff** (`payoff`, [`crate::payoff`]): a frame weighs its culling (everything but
//!   rasterization: the occluder walk, the N-buffer builds, the tests, the read-back) against
//!   the triangles its tests removed times the measured cost of a triangle
//!   ([`FramePayoff::paid`]). Across frames ([`crate::direct`]): after a culled frame slower,
//!   per triangle in view, than a measured direct frame, runs of 8, 16 .. 64 frames (doubling
//!   after each probe that loses, back to 8 after one that wins) are drawn by an embedded
//!   `frustum` (counter `payoff_direct`): what `frustum` draws, the way it draws it (whole
//!   instances and its own mesh BVHs). A frame that finds no occluder at all (an empty depth
//!   buffer hides nothing) is drawn the same way, without counting as a probe (counter
//!   `no_occluders`; with `occluders=visible` or `both` its visible objects are read back
//!   for the next frame). The renderer's first culled frame (frames drawn directly, or that
//!   found no occluder, do not count) is screened once its occluders are drawn: when the
//!   triangles under `frustum`'s boxes hidden behind their depth
//!   ([`Hierarchies::hidden_triangles`](crate::frustum::Hierarchies::hidden_triangles): what
//!   the first pass's tests could remove at most, at `frustum`'s granularity; the second pass
//!   may remove more) are less than [`FIRST_SCREEN_SHARE`] of the work, the tests are not
//!   expected to pay and the frame is drawn again directly, untested, and measured as the
//!   first direct frame (counters `payoff_screened`, `payoff_direct`); weighed as a culled
//!   frame that lost, it starts a run of direct frames (when it took at least
//!   [`MIN_ALLOWANCE_TIME`](crate::payoff::MIN_ALLOWANCE_TIME)). A forest or a city seen from outside no longer pays its tests and its small draws
//!   first. The screening counts triangles, not time: it holds on small scenes too.
//!
//! # First frame
//! With `occluders=visible` and no previous frame (and after a resolution change) the
//! occluder set is empty: the N-buffer of an empty depth buffer culls nothing, so the first
//! frame is frustum culling. With `visible` or `both`, each frame's visible objects are read
//! back from the item buffer (exact, not the set of test survivors) and become the next
//! frame's occluders; `near` needs no read-back.
//!
//! # Deviations
//! - Occluders (default `near`): the paper selects last frame's visible set; on walks whose
//!   views jump (a street snake) that set is small and mostly out of view.
//! - Additions not in the paper: `scale`, `passes=2` and `payoff` (above); the paper builds
//!   one full-resolution N-buffer per frame and always culls.
//! - Software throughout: the N-buffer lookups are plain loads (the paper read pixels back
//!   from GPU textures, §4.2).
//! - The screen box of a bounding box is the pixel-centre rectangle of its 8 projected
//!   corners widened by 1/64 pixel, its depth the nearest corner's widened by 1e-5 (relative),
//!   the same margins as [`occult_raster::query_box`]; boxes reaching the near plane are never
//!   culled. A tie in depth is not culled (the tie can be won on item id).
//! - `cover=one` replaces the four-square cover by the one-square query (ablation).
//! - `test=query` replaces the N-buffer by an occlusion query of each box against the depth
//!   buffer ([`occult_raster::query_box_counted`]: the pixels of its projected silhouette,
//!   as a hardware query with back-face culling compares them), on the same objects and
//!   nodes, to measure Table 2's OQ columns (§4.2). No N-buffer is built; the counter
//!   `depth_comparisons` is the pixels compared (the lookups with the N-buffer).
//!
//! # Cost
//! Per frame: the occluder walk (projecting the boxes of the objects and nodes in the
//! frustum), drawing the occluders, one reduction and N-buffer build (resolution only; two
//! with `passes=2`), 4 loads per tested box (one when its rectangle is a single pixel, none
//! when it covers no pixel centre), and with `visible` or `both` a pass over the item buffer.
//! Not worth it when nearly everything is visible: then `payoff` draws directly.

pub mod particles;
pub mod shadows;

use std::sync::Arc;
use std::time::Instant;

use occult_core::{Aabb, Affine3A, Containment, Frustum, ItemId, NodeId, NodeKind, Scene, Vec3, View, NO_ITEM};
use occult_raster::{query_box_counted, Draw, DrawTriangles, Extremum, Frame, NBuffer, PixelRect, Rasterizer};
use occult_spatial::Bvh;
use rayon::prelude::*;

use crate::direct::DirectFrames;
use crate::nodes::{per_node, triangle_boxes};
use crate::payoff::{FramePayoff, Payoff};
use crate::walk::{cull_bvh, test_box};
use crate::{AlgorithmInfo, FrameStats, ParamDoc, Phase, RenderError, RenderOptions, Renderer, Result};

/// Largest number of objects (mesh instances × triangle chunks) the renderer flattens.
pub const MAX_OBJECTS: u64 = 1 << 24;

/// Registry entry of [`NBufferCulling`].
pub static INFO: AlgorithmInfo = AlgorithmInfo {
    name: "nbuffer",
    summary: "N-buffer occlusion culling (Décoret 2005): the objects with the largest screen boxes (or last frame's visible ones) as occluders, 4-lookup box tests",
    params: &[
        ParamDoc {
            key: "hierarchy",
            default: "bvh",
            help: "test a BVH over the objects top-down (bvh) or every object (flat)",
        },
        ParamDoc {
            key: "cover",
            default: "four",
            help: "rectangle query: four-square cover of Fig. 3 (four) or one square (one)",
        },
        ParamDoc {
            key: "test",
            default: "nbuffer",
            help: "box test: N-buffer lookups (nbuffer) or an occlusion query of the box's silhouette against the depth buffer (query, Table 2's OQ)",
        },
        ParamDoc {
            key: "leaf",
            default: "256",
            help: "triangles per object: meshes above this are split into BVH leaves (>= 1)",
        },
        ParamDoc {
            key: "group_leaf",
            default: "4",
            help: "objects per leaf of the hierarchy over objects (>= 1)",
        },
        ParamDoc {
            key: "occluders",
            default: "near",
            help: "occluders: last frame's visible objects (visible, the paper), the objects of this view with the largest screen boxes (near), or both",
        },
        ParamDoc {
            key: "near_area",
            default: "0.004",
            help: "near occluders: least share of the screen an object's box must cover (0..=1)",
        },
        ParamDoc {
            key: "near_max",
            default: "128",
            help: "near occluders: most objects taken, largest screen boxes first",
        },
        ParamDoc {
            key: "scale",
            default: "2",
            help: "pixels per side of one N-buffer sample (1, 2, 4 or 8): the depth is first reduced to the farthest of each block (a cheaper build, a coarser test)",
        },
        ParamDoc {
            key: "passes",
            default: "2",
            help: "1: draw every survivor; 2: draw the nearer half, rebuild the N-buffer, test the farther half again (skipped for 3 frames after one where the rebuild cost more than it saved)",
        },
        ParamDoc {
            key: "payoff",
            default: "on",
            help: "draw runs of frames as frustum does (8, 16 .. 64 frames, culling probed between) while culled frames are slower than such direct frames (on|off)",
        },
    ],
    counters: &[
        "occluders_drawn",
        "near_occluders",
        "depth_comparisons",
        "nbuffer_lookups",
        "rect_pixels",
        "survivors_drawn",
        "payoff_direct",
        "payoff_screened",
        "no_occluders",
        "triangles_saved",
        "second_pass_saved",
    ],
    conservative: true,
    bands: true,
    build: |scene, options, params| {
        let defaults = NBufferOptions::default();
        let no = NBufferOptions {
            hierarchy: params.choice("hierarchy", &["bvh", "flat"], "bvh")? == "bvh",
            four_square: params.choice("cover", &["four", "one"], "four")? == "four",
            query: params.choice("test", &["nbuffer", "query"], "nbuffer")? == "query",
            leaf_size: params.get("leaf", defaults.leaf_size)?,
            group_leaf_size: params.get("group_leaf", defaults.group_leaf_size)?,
            occluders: match params.choice("occluders", &["visible", "near", "both"], "near")? {
                "visible" => Occluders::Visible,
                "near" => Occluders::Near,
                _ => Occluders::Both,
            },
            near_area: params.get("near_area", defaults.near_area)?,
            near_max: params.get("near_max", defaults.near_max)?,
            payoff: params.flag("payoff", defaults.payoff)?,
            scale: params.get("scale", defaults.scale)?,
            passes: params.get("passes", defaults.passes)?,
        };
        Ok(Box::new(NBufferCulling::with_options(scene, options, &no)?))
    },
};

/// Tunables of [`NBufferCulling`].
#[derive(Clone, Debug, PartialEq)]
pub struct NBufferOptions {
    /// Test a BVH over the objects top-down (true) or every object (false).
    pub hierarchy: bool,
    /// Four-square cover (true) or one-square query (false).
    pub four_square: bool,
    /// Test boxes with an occlusion query against the depth buffer
    /// ([`occult_raster::query_box_counted`]) instead of the N-buffer (Table 2's OQ columns;
    /// no N-buffer is built).
    pub query: bool,
    /// Triangles per object (≥ 1): larger meshes are split into BVH leaves.
    pub leaf_size: usize,
    /// Objects per leaf of the hierarchy (≥ 1).
    pub group_leaf_size: usize,
    /// Which objects are drawn first, as occluders.
    pub occluders: Occluders,
    /// Near occluders: the least share of the screen (0..=1) an object's screen box covers.
    pub near_area: f64,
    /// Near occluders: the most objects taken, largest screen boxes first.
    pub near_max: usize,
    /// Draw runs of frames as `frustum` does while culled frames are slower than such direct
    /// frames ([`crate::direct`]).
    pub payoff: bool,
    /// Pixels per side of one N-buffer sample (1, 2, 4 or 8): the depth map is reduced to
    /// the farthest depth of each `scale × scale` block before the N-buffer is built over it.
    pub scale: u32,
    /// 1, or 2: the nearer half of the survivors is drawn, the N-buffer rebuilt and the
    /// farther half tested again (skipped for [`SECOND_PASS_SKIP`] frames after a frame
    /// where the rebuild cost more than the drawing it saved).
    pub passes: u32,
}

/// Which objects a frame draws first, before building the N-buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Occluders {
    /// §3.1: the objects visible in the previous frame (read back from its item buffer).
    Visible,
    /// The objects of this view whose screen boxes are largest (nearest, biggest).
    Near,
    /// Both sets.
    Both,
}

impl Occluders {
    fn visible(self) -> bool {
        self != Occluders::Near
    }

    fn near(self) -> bool {
        self != Occluders::Visible
    }
}

/// Frames without a second pass after one that did not pay (`passes=2`).
pub const SECOND_PASS_SKIP: u32 = 3;

/// Share of the work that must lie hidden behind the first frame's occluders for its tests to
/// be run (with payoff on): below it, the frame is drawn directly.
pub const FIRST_SCREEN_SHARE: f64 = 0.125;

impl Default for NBufferOptions {
    fn default() -> Self {
        Self {
            hierarchy: true,
            four_square: true,
            query: false,
            leaf_size: 256,
            group_leaf_size: 4,
            occluders: Occluders::Near,
            near_area: 0.004,
            near_max: 128,
            payoff: true,
            scale: 2,
            passes: 2,
        }
    }
}

impl NBufferOptions {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a zero leaf size, a `scale` other than 1, 2, 4 or 8,
    /// `passes` other than 1 or 2, or a `near_area` outside 0..=1.
    pub fn validate(&self) -> Result<()> {
        if self.leaf_size == 0 || self.group_leaf_size == 0 {
            return Err(RenderError::BadParameter(format!(
                "nbuffer: leaf={} and group_leaf={} must be at least 1",
                self.leaf_size, self.group_leaf_size
            )));
        }
        if ![1, 2, 4, 8].contains(&self.scale) {
            return Err(RenderError::BadParameter(format!(
                "nbuffer: scale={} must be 1, 2, 4 or 8",
                self.scale
            )));
        }
        if self.passes == 0 || self.passes > 2 {
            return Err(RenderError::BadParameter(format!(
                "nbuffer: passes={} must be 1 or 2",
                self.passes
            )));
        }
        if !(0.0..=1.0).contains(&self.near_area) {
            return Err(RenderError::BadParameter(format!(
                "nbuffer: near_area={} must be in 0..=1",
                self.near_area
            )));
        }
        Ok(())
    }
}

/// One object: a mesh instance or a leaf of its mesh's BVH.
#[derive(Clone, Debug)]
struct Object {
    world_from_object: Affine3A,
    /// World box, widened for rounding.
    bounds: Aabb,
    first_item: ItemId,
    mesh: NodeId,
    /// Node index of the leaf in the mesh's BVH, or `u32::MAX` for the whole mesh.
    leaf_node: u32,
    /// Rank of its mesh instance in item order.
    instance: u32,
    /// Its triangles.
    triangles: u32,
}

/// A mesh instance's item range and its objects.
#[derive(Clone, Copy, Debug)]
struct InstanceRecord {
    first_item: ItemId,
    end_item: ItemId,
    first_object: u32,
    mesh: NodeId,
}

/// The N-buffer occlusion-culling renderer.
pub struct NBufferCulling {
    scene: Arc<Scene>,
    raster: Rasterizer,
    options: NBufferOptions,
    objects: Vec<Object>,
    /// Per scene node: the BVH over a large mesh's triangles.
    mesh_bvhs: Vec<Option<Bvh>>,
    /// Per scene node: a large mesh's triangle → its leaf's rank among the mesh's leaves.
    triangle_leaf: Vec<Option<Vec<u32>>>,
    /// Mesh instances in item order.
    instances: Vec<InstanceRecord>,
    /// BVH over the objects' world boxes (hierarchy=bvh).
    hierarchy: Option<Bvh>,
    nbuffer: Option<NBuffer>,
    /// Objects visible in the previous frame (per object).
    visible: Vec<bool>,
    /// Objects drawn this frame (scratch).
    drawn: Vec<bool>,
    /// Resolution of the previous frame (occluders are dropped when it changes).
    last_size: (u32, u32),
    /// The flat list's batched tests (scratch).
    batch: Batch,
    /// Per node of `hierarchy`: the triangles of its objects (what culling it saves).
    node_triangles: Vec<u64>,
    /// Whether culling pays ([`crate::payoff`]).
    payoff: Payoff,
    /// What draws the direct frames and when (`payoff=on`).
    direct: Option<DirectFrames>,
    /// The depth map reduced to `scale × scale` blocks (scratch).
    coarse_depth: Vec<f32>,
    /// Frames still to render without the second pass.
    second_pass_skip: u32,
}

impl NBufferCulling {
    /// Flattens `scene` into objects and builds the hierarchy over them.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a zero leaf size or more than [`MAX_OBJECTS`]
    /// objects (checked before allocating them); raster configuration errors.
    pub fn with_options(scene: Arc<Scene>, options: &RenderOptions, no: &NBufferOptions) -> Result<Self> {
        no.validate()?;
        let raster = crate::scene_rasterizer(&scene, options)?;
        let leaf = no.leaf_size;
        let mesh_bvhs: Vec<Option<Bvh>> = per_node(&raster, &scene, |node| match node.kind() {
            NodeKind::Mesh(m) if m.triangle_count() > leaf => Some(Bvh::build(&triangle_boxes(m), leaf)),
            _ => None,
        });
        let leaves_of = |bvh: &Bvh| -> Vec<u32> {
            (0..bvh.nodes().len() as u32)
                .filter(|&n| bvh.nodes()[n as usize].is_leaf())
                .collect()
        };
        // Objects per node, counted bottom-up (children come before parents in `nodes()`? not
        // guaranteed: memoised recursion instead).
        let mut counts: Vec<Option<u64>> = vec![None; scene.nodes().len()];
        fn count(scene: &Scene, id: NodeId, mesh_bvhs: &[Option<Bvh>], counts: &mut [Option<u64>]) -> u64 {
            if let Some(c) = counts[id.index()] {
                return c;
            }
            let c = match scene.node(id).kind() {
                NodeKind::Mesh(m) => match &mesh_bvhs[id.index()] {
                    Some(bvh) => bvh.nodes().iter().filter(|n| n.is_leaf()).count() as u64,
                    None => u64::from(m.triangle_count() > 0),
                },
                NodeKind::Group(instances) => instances.iter().fold(0u64, |acc, i| {
                    acc.saturating_add(count(scene, i.child, mesh_bvhs, counts))
                }),
            };
            counts[id.index()] = Some(c);
            c
        }
        let object_count = count(&scene, scene.root(), &mesh_bvhs, &mut counts);
        if object_count > MAX_OBJECTS {
            return Err(RenderError::BadParameter(format!(
                "nbuffer: the scene flattens to {object_count} objects, more than {MAX_OBJECTS}; raise leaf (now {leaf})"
            )));
        }
        let leaves: Vec<Option<Vec<u32>>> = mesh_bvhs.iter().map(|b| b.as_ref().map(leaves_of)).collect();
        let triangle_leaf: Vec<Option<Vec<u32>>> = mesh_bvhs
            .iter()
            .zip(&leaves)
            .map(|(b, l)| {
                let (bvh, l) = (b.as_ref()?, l.as_ref()?);
                let mut t = vec![0u32; bvh.primitive_indices().len()];
                for (rank, &n) in l.iter().enumerate() {
                    for &tri in &bvh.primitive_indices()[bvh.nodes()[n as usize].range()] {
                        t[tri as usize] = rank as u32;
                    }
                }
                Some(t)
            })
            .collect();
        let mut objects = Vec::with_capacity(object_count as usize);
        let mut instances = Vec::new();
        scene.for_each_mesh_instance(|world_from_object, mesh_id, mesh, first_item| {
            if mesh.triangle_count() == 0 {
                return;
            }
            let instance = instances.len() as u32;
            instances.push(InstanceRecord {
                first_item,
                end_item: first_item + mesh.triangle_count() as u64,
                first_object: objects.len() as u32,
                mesh: mesh_id,
            });
            let mut push = |object_bounds: Aabb, leaf_node: u32, triangles: usize| {
                objects.push(Object {
                    world_from_object: *world_from_object,
                    bounds: widen(object_bounds.transformed(world_from_object)),
                    first_item,
                    mesh: mesh_id,
                    leaf_node,
                    instance,
                    triangles: triangles as u32,
                })
            };
            match (&mesh_bvhs[mesh_id.index()], &leaves[mesh_id.index()]) {
                (Some(bvh), Some(l)) => {
                    for &n in l {
                        let node = &bvh.nodes()[n as usize];
                        push(node.bounds, n, node.range().len());
                    }
                }
                _ => push(scene.node(mesh_id).bounds(), u32::MAX, mesh.triangle_count()),
            }
        });
        let hierarchy = no.hierarchy.then(|| {
            let boxes: Vec<Aabb> = objects.iter().map(|o| o.bounds).collect();
            Bvh::build(&boxes, no.group_leaf_size)
        });
        let node_triangles = hierarchy.as_ref().map_or_else(Vec::new, |bvh| {
            // Children come after their parent (first child `n + 1`, second child later):
            // summed in reverse.
            let nodes = bvh.nodes();
            let mut t = vec![0u64; nodes.len()];
            for n in (0..nodes.len()).rev() {
                let node = &nodes[n];
                t[n] = if node.is_leaf() {
                    bvh.primitive_indices()[node.range()]
                        .iter()
                        .map(|&i| u64::from(objects[i as usize].triangles))
                        .sum()
                } else {
                    t[n + 1] + t[node.second_child as usize]
                };
            }
            t
        });
        let n = objects.len();
        let payoff = Payoff::new(no.payoff, scene.item_count());
        let direct = match no.payoff {
            true => Some(DirectFrames::new(scene.clone(), &raster)?),
            false => None,
        };
        Ok(Self {
            scene,
            raster,
            options: no.clone(),
            objects,
            mesh_bvhs,
            triangle_leaf,
            instances,
            hierarchy,
            nbuffer: None,
            visible: vec![false; n],
            drawn: vec![false; n],
            last_size: (0, 0),
            batch: Batch::default(),
            node_triangles,
            payoff,
            direct,
            coarse_depth: Vec::new(),
            second_pass_skip: 0,
        })
    }

    /// The objects in the frustum whose screen boxes cover at least `near_area` of the
    /// screen, largest first, at most `near_max` (a box reaching the near plane counts as the
    /// whole screen).
    fn near_occluders(&self, frustum: &Frustum, project: &Projector, stats: &mut FrameStats) -> Vec<usize> {
        let least = (self.options.near_area * project.width * project.height).max(1.0);
        let screen = project.width * project.height;
        let mut found: Vec<(f64, usize)> = Vec::new();
        let mut consider = |i: usize| {
            let area = match project.screen(&self.objects[i].bounds) {
                Screen::Empty => return,
                Screen::Anywhere => screen,
                Screen::Rect(rect, _) => rect.area() as f64,
            };
            if area >= least {
                found.push((area, i));
            }
        };
        match &self.hierarchy {
            Some(bvh) => cull_bvh(stats, bvh, frustum, |stats, _, node, inside| {
                if node.is_leaf() {
                    for &i in &bvh.primitive_indices()[node.range()] {
                        let i = i as usize;
                        if inside || test_box(stats, frustum, &self.objects[i].bounds) != Containment::Outside {
                            consider(i);
                        }
                    }
                    return false;
                }
                // A subtree whose whole screen box is smaller than the least area holds no
                // object that large.
                match project.screen(&node.bounds) {
                    Screen::Empty => false,
                    Screen::Anywhere => true,
                    Screen::Rect(rect, _) => rect.area() as f64 >= least,
                }
            }),
            None => {
                for i in 0..self.objects.len() {
                    if test_box(stats, frustum, &self.objects[i].bounds) != Containment::Outside {
                        consider(i);
                    }
                }
            }
        }
        found.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        found.truncate(self.options.near_max);
        found.into_iter().map(|(_, i)| i).collect()
    }

    /// §2: builds the N-buffer over `frame`'s depth (reduced to `scale × scale` blocks
    /// first), adding the time to [`Phase::DepthStructure`].
    fn build_nbuffer(&mut self, frame: &Frame, stats: &mut FrameStats) -> Result<()> {
        let t = Instant::now();
        let (w, h) = (frame.width(), frame.height());
        let shift = self.options.scale.trailing_zeros();
        let coarse = &mut self.coarse_depth;
        let nbuffer = &mut self.nbuffer;
        let result = self.raster.install(|| {
            let (depth, cw, ch) = if shift == 0 {
                (frame.depth(), w, h)
            } else {
                let (cw, ch) = reduce_farthest(frame.depth(), w, h, shift, coarse);
                (&coarse[..], cw, ch)
            };
            let levels = NBuffer::default_level_count(cw, ch);
            match nbuffer {
                Some(nb) => nb.rebuild(depth, cw, ch, levels),
                None => NBuffer::new(Extremum::Min, depth, cw, ch).map(|nb| {
                    *nbuffer = Some(nb);
                }),
            }
        });
        result?;
        stats.phases.add(Phase::DepthStructure, t.elapsed());
        Ok(())
    }

    /// Marks the objects whose items are in `frame` as visible (the next frame's occluders).
    fn read_back_visible(&mut self, frame: &Frame) {
        self.visible.fill(false);
        let mut current: Option<InstanceRecord> = None;
        for &item in frame.items() {
            if item == NO_ITEM {
                continue;
            }
            let rec = match current {
                Some(r) if r.first_item <= item && item < r.end_item => r,
                _ => {
                    let k = self.instances.partition_point(|r| r.first_item <= item);
                    let Some(r) = k.checked_sub(1).map(|k| self.instances[k]) else {
                        continue;
                    };
                    if item >= r.end_item {
                        continue;
                    }
                    current = Some(r);
                    r
                }
            };
            let rank = match &self.triangle_leaf[rec.mesh.index()] {
                Some(t) => t[(item - rec.first_item) as usize],
                None => 0,
            };
            self.visible[rec.first_object as usize + rank as usize] = true;
        }
    }
}

/// The draws of objects `indices` (sorted here). A mesh instance split into chunks is drawn
/// whole when more than half of its triangles are asked for: index lists transform each
/// corner once per triangle, a whole mesh shares its vertices (as `frustum` does).
fn draws_of<'a>(
    scene: &'a Scene,
    objects: &[Object],
    mesh_bvhs: &'a [Option<Bvh>],
    view: &View,
    indices: &mut [usize],
) -> Vec<Draw<'a>> {
    indices.sort_unstable();
    let mut draws = Vec::with_capacity(indices.len());
    let mut k = 0;
    while k < indices.len() {
        let o = &objects[indices[k]];
        let mesh = scene.node(o.mesh).mesh().expect("objects are meshes");
        let clip_from_object = view.clip_from_object(&o.world_from_object);
        let whole = |triangles| Draw {
            mesh,
            triangles,
            clip_from_object,
            first_item: o.first_item,
        };
        let bvh = match (&mesh_bvhs[o.mesh.index()], o.leaf_node) {
            (Some(bvh), leaf) if leaf != u32::MAX => bvh,
            _ => {
                draws.push(whole(DrawTriangles::All));
                k += 1;
                continue;
            }
        };
        // The run of chunks of this same instance (objects of an instance are contiguous).
        let mut end = k + 1;
        while end < indices.len() && objects[indices[end]].instance == o.instance {
            end += 1;
        }
        let leaf_range = |i: usize| bvh.nodes()[objects[i].leaf_node as usize].range();
        let asked: usize = indices[k..end].iter().map(|&i| leaf_range(i).len()).sum();
        if asked * 2 > mesh.triangle_count() {
            draws.push(whole(DrawTriangles::All));
        } else {
            for &i in &indices[k..end] {
                draws.push(whole(DrawTriangles::List(&bvh.primitive_indices()[leaf_range(i)])));
            }
        }
        k = end;
    }
    draws
}

/// The rectangle of N-buffer samples (each `2^shift` pixels a side) that holds every pixel
/// of `rect`; an empty rectangle stays empty (it is hidden: it draws nothing).
fn coarse(rect: PixelRect, shift: u32) -> PixelRect {
    if shift == 0 || rect.x0 >= rect.x1 || rect.y0 >= rect.y1 {
        return rect;
    }
    let up = |v: u32| (v >> shift) + u32::from(v & ((1 << shift) - 1) != 0);
    PixelRect {
        x0: rect.x0 >> shift,
        y0: rect.y0 >> shift,
        x1: up(rect.x1),
        y1: up(rect.y1),
    }
}

/// Reduces the `w × h` depth map to one sample per `2^shift`-pixel square block (partial at
/// the right and bottom edges): the farthest depth of the block (the least, in reversed Z; a
/// NaN reads as `-inf`, the farthest), so an object nearer than a sample is nearer than every
/// pixel of its block. Fills `out` and returns its size; runs on the current rayon pool.
fn reduce_farthest(depth: &[f32], w: u32, h: u32, shift: u32, out: &mut Vec<f32>) -> (u32, u32) {
    let b = 1usize << shift;
    let (w, h) = (w as usize, h as usize);
    let (cw, ch) = (w.div_ceil(b), h.div_ceil(b));
    out.clear();
    out.resize(cw * ch, f32::INFINITY);
    out.par_chunks_mut(cw).enumerate().for_each_init(
        || vec![0.0f32; w],
        |acc, (cy, row)| {
            // Down the block's rows first (one vectorizable pass per row), then across.
            acc.fill(f32::INFINITY);
            for src in depth[cy * b * w..((cy + 1) * b).min(h) * w].chunks_exact(w) {
                for (m, &v) in acc.iter_mut().zip(src) {
                    let v = if v.is_nan() { f32::NEG_INFINITY } else { v };
                    *m = if v < *m { v } else { *m };
                }
            }
            for (m, block) in row.iter_mut().zip(acc.chunks(b)) {
                *m = block.iter().fold(f32::INFINITY, |a, &v| if v < a { v } else { a });
            }
        },
    );
    (cw as u32, ch as u32)
}

/// [`crate::rasterize`], also telling `payoff` what was rasterized and how long it took.
fn rasterize_weighed(
    raster: &mut Rasterizer,
    view: &View,
    frame: &mut Frame,
    draws: &[Draw<'_>],
    stats: &mut FrameStats,
    payoff: &mut FramePayoff,
) {
    let (t, before) = (Instant::now(), stats.triangles_submitted);
    crate::rasterize(raster, view, frame, draws, stats);
    payoff.rasterized(stats.triangles_submitted - before, t.elapsed(), false);
}

/// Widens a world box by a relative 1e-5 of its coordinates, so that rounding in the
/// transforms cannot leave a vertex outside it.
fn widen(b: Aabb) -> Aabb {
    if b.is_empty() {
        return b;
    }
    let pad = b.min.abs().max(b.max.abs()).max_element() * 1e-5 + 1e-30;
    Aabb::new(b.min - Vec3::splat(pad), b.max + Vec3::splat(pad))
}

/// Depth comparisons and rectangle pixels of a frame's tests.
#[derive(Default)]
struct Tally {
    /// N-buffer lookups, or the pixels an occlusion query compared (`test=query`).
    comparisons: u64,
    rect_pixels: u64,
}

/// What a world box is tested against.
enum Against<'a> {
    /// §3.1: the N-buffer, with the four-square cover (true) or one square (false).
    NBuffer(&'a NBuffer, bool),
    /// Table 2's OQ: an occlusion query of the box's silhouette against the depth buffer.
    Query(&'a Frame, &'a View),
}

/// Where a world box lands on screen.
enum Screen {
    /// An empty box: nothing to draw.
    Empty,
    /// It reaches the near plane (or behind the eye): it may cover anything.
    Anywhere,
    /// Its pixel-centre rectangle and nearest depth.
    Rect(PixelRect, f32),
}

/// The rectangles of a flat object list, tested in one [`NBuffer::occludes_batch`] call
/// (reused from frame to frame).
#[derive(Default)]
struct Batch {
    objects: Vec<u32>,
    rects: Vec<PixelRect>,
    nearest: Vec<f32>,
    hidden: Vec<bool>,
}

impl Batch {
    fn clear(&mut self) {
        self.objects.clear();
        self.rects.clear();
        self.nearest.clear();
    }

    fn push(&mut self, object: usize, rect: PixelRect, nearest: f32) {
        self.objects.push(object as u32);
        self.rects.push(rect);
        self.nearest.push(nearest);
    }

    /// Tests every rectangle (into `hidden`); returns the lookups made.
    fn test(&mut self, nbuffer: &NBuffer) -> Result<u64> {
        self.hidden.clear();
        self.hidden.resize(self.rects.len(), false);
        Ok(nbuffer.occludes_batch(&self.rects, &self.nearest, &mut self.hidden)?)
    }
}

/// The screen test of a world box.
struct BoxTest<'a> {
    against: Against<'a>,
    project: Projector,
    /// log2 of the N-buffer's pixels per sample side.
    shift: u32,
}

/// Where world boxes land on the screen of a view.
#[derive(Clone, Copy)]
struct Projector {
    clip_from_world: occult_core::Mat4,
    width: f64,
    height: f64,
}

impl Projector {
    /// The box's screen rectangle (pixel centres) and nearest depth.
    fn screen(&self, b: &Aabb) -> Screen {
        if b.is_empty() {
            return Screen::Empty;
        }
        let clip = b.corners().map(|c| self.clip_from_world * c.extend(1.0));
        if clip.iter().any(|c| !c.is_finite() || c.z * (1.0 + 1e-5) > c.w) {
            return Screen::Anywhere;
        }
        let (mut minx, mut maxx, mut miny, mut maxy) =
            (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        let mut nearest = 0.0f32;
        for c in &clip {
            let (x, y, w) = (c.x as f64, c.y as f64, c.w as f64);
            let sx = (x / w * 0.5 + 0.5) * self.width;
            let sy = (0.5 - y / w * 0.5) * self.height;
            minx = minx.min(sx);
            maxx = maxx.max(sx);
            miny = miny.min(sy);
            maxy = maxy.max(sy);
            nearest = nearest.max(c.z / c.w);
        }
        let nearest = nearest * (1.0 + 1e-5);
        let margin = 1.0 / 64.0;
        // Pixel centres (x + 0.5) inside [min - margin, max + margin], clamped to the screen.
        let lo = |v: f64| (v - margin - 0.5).ceil().clamp(0.0, 1e9) as u32;
        let hi = |v: f64, size: f64| ((v + margin - 0.5).floor() + 1.0).clamp(0.0, size) as u32;
        let rect = PixelRect {
            x0: lo(minx),
            y0: lo(miny),
            x1: hi(maxx, self.width),
            y1: hi(maxy, self.height),
        };
        Screen::Rect(rect, nearest)
    }
}

impl BoxTest<'_> {
    /// True when the box is hidden; adds the depth comparisons made and the pixels of the
    /// tested rectangle to `tally`. Boxes reaching the near plane are never hidden and are
    /// not tested (in both modes, so both test the same boxes).
    fn hidden(&self, b: &Aabb, tally: &mut Tally) -> bool {
        let (rect, nearest) = match self.project.screen(b) {
            Screen::Empty => return true,
            Screen::Anywhere => return false,
            Screen::Rect(rect, nearest) => (rect, nearest),
        };
        tally.rect_pixels += rect.area();
        match self.against {
            Against::NBuffer(nbuffer, true) => {
                let (hidden, n) = nbuffer.occludes(coarse(rect, self.shift), nearest);
                tally.comparisons += u64::from(n);
                hidden
            }
            Against::NBuffer(nbuffer, false) => {
                let q = nbuffer.query_one(coarse(rect, self.shift));
                tally.comparisons += u64::from(q.lookups);
                q.lookups == 0 || nearest < q.depth
            }
            Against::Query(frame, view) => {
                // Deviation: the software occlusion query counts every pixel of the
                // silhouette (no early out), as a hardware query's sample count does.
                let q = query_box_counted(frame, view, &self.project.clip_from_world, b);
                tally.comparisons += q.comparisons;
                q.samples == 0
            }
        }
    }
}

impl Renderer for NBufferCulling {
    fn name(&self) -> &'static str {
        "nbuffer"
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        // Payoff: while culled frames are slower than direct ones, runs of frames are drawn by
        // `frustum` (the same objects drawn the way it draws them), culling probed between.
        crate::check_frame(view, frame)?;
        let begun = Instant::now();
        if let Some(direct) = &mut self.direct {
            if let Some(stats) = direct.render_if_due(&mut self.raster, view, frame)? {
                return crate::end_frame(&self.raster, stats);
            }
        }
        let (w, h) = (view.width(), view.height());
        if self.last_size != (w, h) {
            self.visible.fill(false);
            self.last_size = (w, h);
        }
        let frustum = view.frustum(&Affine3A::IDENTITY);
        self.drawn.fill(false);
        let project = Projector {
            clip_from_world: view.clip_from_object(&Affine3A::IDENTITY),
            width: f64::from(w),
            height: f64::from(h),
        };

        // Occluders: last frame's visible objects still in the frustum (§3.1), and the
        // objects of this view with the largest screen boxes. Chosen before the frame is
        // cleared: with none, nothing can be culled.
        let t = Instant::now();
        let mut walk = FrameStats::default();
        let mut occluders = Vec::new();
        if self.options.occluders.visible() {
            for i in 0..self.objects.len() {
                if self.visible[i] {
                    if test_box(&mut walk, &frustum, &self.objects[i].bounds) == Containment::Outside {
                        continue;
                    }
                    self.drawn[i] = true;
                    occluders.push(i);
                }
            }
        }
        let mut near_count = 0;
        if self.options.occluders.near() {
            let near = self.near_occluders(&frustum, &project, &mut walk);
            near_count = near.len() as u64;
            for i in near {
                if !self.drawn[i] {
                    self.drawn[i] = true;
                    occluders.push(i);
                }
            }
        }
        if let (Some(direct), true) = (&mut self.direct, occluders.is_empty()) {
            // Nothing to occlude with: an empty depth buffer hides nothing.
            let mut stats = direct.render(&mut self.raster, view, frame)?;
            stats.counters.add("no_occluders", 1);
            stats.phases.add(Phase::Cull, t.elapsed());
            if self.options.occluders.visible() {
                // Its visible objects are the next frame's occluders (else every frame after
                // would find none either).
                let t = Instant::now();
                self.read_back_visible(frame);
                stats.phases.add(Phase::Other, t.elapsed());
            }
            return crate::end_frame(&self.raster, stats);
        }
        let selection = t.elapsed();
        let (start, cleared_at, mut stats) = crate::begin_frame(&mut self.raster, view, frame)?;
        let start = start - selection;
        let mut payoff = self.payoff.begin(cleared_at - selection);
        let t = Instant::now() - selection;
        stats.nodes_visited += walk.nodes_visited;
        stats.boxes_tested += walk.boxes_tested;
        stats.boxes_culled += walk.boxes_culled;
        if self.options.occluders.near() {
            stats.counters.add("near_occluders", near_count);
        }
        let draws = draws_of(&self.scene, &self.objects, &self.mesh_bvhs, view, &mut occluders);
        stats.phases.add(Phase::Cull, t.elapsed());
        rasterize_weighed(&mut self.raster, view, frame, &draws, &mut stats, &mut payoff);
        drop(draws);
        crate::check_cancel(&self.raster)?;
        stats.counters.add("occluders_drawn", occluders.len() as u64);
        if let (Some(direct), true) = (&mut self.direct, self.payoff.first_frame()) {
            // The first culled frame, with no last frame's visible objects: when the triangles
            // under `frustum`'s boxes hidden behind the occluders' depth (what the first pass's
            // tests could remove at most, at `frustum`'s granularity) are less than
            // FIRST_SCREEN_SHARE of the work, the tests are not expected to pay and the frame
            // is drawn again directly, measured.
            let t = Instant::now();
            let hidden = direct.hidden_triangles(view, frame)?;
            stats.phases.add(Phase::Cull, t.elapsed());
            if (hidden as f64) < FIRST_SCREEN_SHARE * direct.work() as f64 {
                stats.counters.add(crate::direct::SCREENED, 1);
                direct.redraw(&mut self.raster, view, frame, &mut stats)?;
                self.payoff.end(&payoff);
                let t = Instant::now();
                direct.culled(view, frame, begun.elapsed(), &mut stats, false)?;
                stats.phases.add(Phase::Other, t.elapsed());
                stats.total = start.elapsed();
                return crate::end_frame(&self.raster, stats);
            }
        }

        // §2: the N-buffer of the occluders' depth (min variant: farthest depth); none for
        // occlusion queries, which read the depth buffer itself.
        let shift = self.options.scale.trailing_zeros();
        if !self.options.query {
            self.build_nbuffer(frame, &mut stats)?;
        }

        // §3.1: test every object (through the hierarchy or flat), keep the survivors.
        let t = Instant::now();
        let against = match &self.nbuffer {
            Some(nbuffer) if !self.options.query => Against::NBuffer(nbuffer, self.options.four_square),
            _ => Against::Query(&*frame, view),
        };
        let test = BoxTest {
            against,
            project,
            shift,
        };
        let mut tally = Tally::default();
        let mut survivors = Vec::new();
        let objects = &self.objects;
        let drawn = &self.drawn;
        let mut saved = 0u64;
        let mut test_object = |i: usize, inside: bool, stats: &mut FrameStats, tally: &mut Tally, saved: &mut u64| {
            if drawn[i] {
                return;
            }
            let b = &objects[i].bounds;
            if !inside && test_box(stats, &frustum, b) == Containment::Outside {
                return;
            }
            stats.rects_tested += 1;
            if test.hidden(b, tally) {
                stats.rects_culled += 1;
                *saved += u64::from(objects[i].triangles);
            } else {
                survivors.push(i);
            }
        };
        match &self.hierarchy {
            Some(bvh) if !bvh.nodes().is_empty() => {
                let node_triangles = &self.node_triangles;
                cull_bvh(&mut stats, bvh, &frustum, |stats, n, node, inside| {
                    if node.is_leaf() {
                        for &i in &bvh.primitive_indices()[node.range()] {
                            test_object(i as usize, inside, stats, &mut tally, &mut saved);
                        }
                        return false;
                    }
                    // §4.2: an inner node is tested like an object; a hidden one hides its
                    // subtree (occluders in it were drawn: what it saves is an upper bound).
                    stats.rects_tested += 1;
                    if test.hidden(&node.bounds, &mut tally) {
                        stats.rects_culled += 1;
                        saved += node_triangles[n as usize];
                        return false;
                    }
                    true
                })
            }
            _ => match test.against {
                Against::NBuffer(nbuffer, true) => {
                    // §3.1 over the flat list: every object's rectangle first, then one
                    // batched test (same answers as one call each; the lookups overlap).
                    let batch = &mut self.batch;
                    batch.clear();
                    for (i, object) in objects.iter().enumerate() {
                        if drawn[i] || test_box(&mut stats, &frustum, &object.bounds) == Containment::Outside {
                            continue;
                        }
                        stats.rects_tested += 1;
                        match test.project.screen(&object.bounds) {
                            Screen::Empty => stats.rects_culled += 1,
                            Screen::Anywhere => survivors.push(i),
                            Screen::Rect(rect, nearest) => {
                                tally.rect_pixels += rect.area();
                                batch.push(i, coarse(rect, shift), nearest);
                            }
                        }
                    }
                    tally.comparisons += batch.test(nbuffer)?;
                    for (&i, &hidden) in batch.objects.iter().zip(&batch.hidden) {
                        if hidden {
                            stats.rects_culled += 1;
                            saved += u64::from(objects[i as usize].triangles);
                        } else {
                            survivors.push(i as usize);
                        }
                    }
                }
                _ => {
                    for i in 0..objects.len() {
                        test_object(i, false, &mut stats, &mut tally, &mut saved);
                    }
                }
            },
        }
        payoff.saved(saved);
        stats.counters.add("triangles_saved", saved);
        // Table 2: the depth comparisons of the tests (N-buffer lookups, or the pixels the
        // occlusion queries compared).
        stats.counters.add("depth_comparisons", tally.comparisons);
        if !self.options.query {
            stats.counters.add("nbuffer_lookups", tally.comparisons);
        }
        // The pixels of the tested boxes' screen rectangles (what a per-pixel test of the
        // rectangles, `query_rect`, would compare).
        stats.counters.add("rect_pixels", tally.rect_pixels);
        // Second pass: the nearer half of the survivors first; the farther half is tested
        // again against the N-buffer of the new depth.
        let mut later = Vec::new();
        let second_pass = self.options.passes == 2 && self.second_pass_skip == 0;
        self.second_pass_skip = self.second_pass_skip.saturating_sub(1);
        if second_pass && !self.options.query && survivors.len() >= 2 {
            let mut keyed: Vec<(f32, usize)> = survivors
                .iter()
                .map(|&i| match project.screen(&self.objects[i].bounds) {
                    Screen::Rect(_, nearest) => (nearest, i),
                    _ => (f32::INFINITY, i),
                })
                .collect();
            keyed.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
            let half = keyed.len() / 2;
            survivors = keyed[..half].iter().map(|&(_, i)| i).collect();
            later = keyed[half..].iter().map(|&(_, i)| i).collect();
        }
        stats.counters.add("survivors_drawn", survivors.len() as u64);
        let draws = draws_of(&self.scene, &self.objects, &self.mesh_bvhs, view, &mut survivors);
        stats.phases.add(Phase::Cull, t.elapsed());
        rasterize_weighed(&mut self.raster, view, frame, &draws, &mut stats, &mut payoff);
        drop(draws);
        if !later.is_empty() {
            let t = Instant::now();
            self.build_nbuffer(frame, &mut stats)?;
            let rebuild = t.elapsed();
            let t = Instant::now();
            let Some(nbuffer) = &self.nbuffer else {
                unreachable!("build_nbuffer succeeded");
            };
            let test = BoxTest {
                against: Against::NBuffer(nbuffer, self.options.four_square),
                project,
                shift,
            };
            let mut saved = 0u64;
            let mut last = Vec::new();
            for i in later {
                stats.rects_tested += 1;
                if test.hidden(&self.objects[i].bounds, &mut tally) {
                    stats.rects_culled += 1;
                    saved += u64::from(self.objects[i].triangles);
                } else {
                    last.push(i);
                }
            }
            payoff.saved(saved);
            stats.counters.add("triangles_saved", saved);
            stats.counters.add("second_pass_saved", saved);
            stats.counters.add("survivors_drawn", last.len() as u64);
            let draws = draws_of(&self.scene, &self.objects, &self.mesh_bvhs, view, &mut last);
            stats.phases.add(Phase::Cull, t.elapsed());
            rasterize_weighed(&mut self.raster, view, frame, &draws, &mut stats, &mut payoff);
            // A second pass whose rebuild cost more than the drawing it saved is skipped for
            // the next frames (this frame's cost of a triangle).
            let ns_per_triangle =
                stats.phases.get(Phase::Raster).as_nanos() as f64 / stats.triangles_submitted.max(1) as f64;
            if (saved as f64) * ns_per_triangle < rebuild.as_nanos() as f64 {
                self.second_pass_skip = SECOND_PASS_SKIP;
            }
        }

        // A cancelled frame leaves last frame's occluders in place.
        crate::check_cancel(&self.raster)?;
        // The exactly visible objects become the next frame's occluders.
        if self.options.occluders.visible() {
            let t = Instant::now();
            self.read_back_visible(frame);
            stats.phases.add(Phase::Other, t.elapsed());
        }
        self.payoff.end(&payoff);
        if let Some(direct) = &mut self.direct {
            let t = Instant::now();
            let paid = self.payoff.last_paid();
            if direct.culled(view, frame, begun.elapsed(), &mut stats, paid)? && self.options.occluders.visible() {
                // Stale by the next probe.
                self.visible.fill(false);
            }
            stats.phases.add(Phase::Other, t.elapsed());
        }
        stats.total = start.elapsed();
        crate::end_frame(&self.raster, stats)
    }

    /// The rasterizer's private frames and the direct frames' screening pyramid (the N-buffer
    /// is made from each frame's depth).
    fn prepare(&mut self, width: u32, height: u32) -> Result<()> {
        crate::prepare_raster(&mut self.raster, &self.scene, width, height);
        if let Some(direct) = &mut self.direct {
            direct.prepare(&mut self.raster, width, height)?;
        }
        // The N-buffer's levels (20 MB of 16-bit keys at 1280×720), made and written now
        // rather than in the first culled frame (over a far map; each frame rebuilds them
        // before a test). `query=on` reads the depth buffer instead.
        if width > 0 && height > 0 && self.nbuffer.is_none() && !self.options.query {
            let b = self.options.scale as usize;
            let (cw, ch) = ((width as usize).div_ceil(b), (height as usize).div_ceil(b));
            self.coarse_depth.clear();
            self.coarse_depth.resize(cw * ch, 0.0);
            let (depth, raster) = (&self.coarse_depth, &self.raster);
            let built = raster.install(|| NBuffer::new(Extremum::Min, depth, cw as u32, ch as u32));
            if let Ok(nb) = built {
                self.nbuffer = Some(nb);
            }
        }
        Ok(())
    }

    fn memory_bytes(&self) -> usize {
        self.objects.capacity() * std::mem::size_of::<Object>()
            + self.instances.capacity() * std::mem::size_of::<InstanceRecord>()
            + self.mesh_bvhs.iter().flatten().map(Bvh::memory_bytes).sum::<usize>()
            + self
                .triangle_leaf
                .iter()
                .flatten()
                .map(|t| t.capacity() * 4)
                .sum::<usize>()
            + self.hierarchy.as_ref().map_or(0, Bvh::memory_bytes)
            + self.nbuffer.as_ref().map_or(0, NBuffer::memory_bytes)
            + self.visible.capacity()
            + self.drawn.capacity()
            + self.batch.objects.capacity() * 4
            + self.batch.rects.capacity() * std::mem::size_of::<PixelRect>()
            + self.batch.nearest.capacity() * 4
            + self.batch.hidden.capacity()
            + self.coarse_depth.capacity() * 4
            + self.direct.as_ref().map_or(0, DirectFrames::memory_bytes)
            + self.raster.memory_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_grid as grid;
    use occult_core::{Camera, Instance, SceneBuilder};

    /// A big wall in front of rows of small grids: most of them hidden.
    fn wall_scene() -> (Arc<Scene>, View) {
        let mut b = SceneBuilder::new();
        let wall = b.add_mesh("wall", grid(8)).expect("a valid mesh adds");
        let small = b.add_mesh("small", grid(4)).expect("a valid mesh adds");
        let mut instances = vec![Instance {
            parent_from_child: Affine3A::from_scale_rotation_translation(
                Vec3::splat(6.0),
                Default::default(),
                Vec3::new(-1.0, -1.0, 1.0),
            ),
            child: wall,
        }];
        instances.extend((0..40).map(|i| Instance {
            parent_from_child: Affine3A::from_translation(Vec3::new(
                (i % 8) as f32 * 0.5,
                (i / 8) as f32 * 0.5,
                -(i % 5) as f32,
            )),
            child: small,
        }));
        let root = b.add_group("scene", instances).expect("a group of known nodes adds");
        let scene = Arc::new(b.build(root).expect("the wall has triangles and builds"));
        let camera = Camera::look_at(Vec3::new(2.0, 1.5, 6.0), Vec3::new(2.0, 1.5, 0.0));
        (scene, View::new(camera, 96, 64).expect("a 96x64 view of the wall"))
    }

    fn zbuffer_frame(scene: &Arc<Scene>, view: &View) -> Frame {
        let mut z = crate::AlgoSpec::parse("zbuffer")
            .expect("zbuffer is a known renderer")
            .build(scene.clone(), &RenderOptions::default())
            .expect("zbuffer builds for any scene");
        let mut f = Frame::new(view.width(), view.height()).expect("a frame of the view's size");
        z.render(view, &mut f).expect("zbuffer renders the wall scene");
        f
    }

    #[test]
    fn coarse_rectangles_hold_every_pixel_and_stay_empty_when_empty() {
        let rect = |x0, y0, x1, y1| PixelRect { x0, y0, x1, y1 };
        let r = rect(3, 4, 9, 5);
        assert_eq!(coarse(r, 0), r);
        assert_eq!(coarse(r, 1), rect(1, 2, 5, 3));
        assert_eq!(coarse(r, 2), rect(0, 1, 3, 2));
        let empty = rect(5, 2, 5, 7);
        assert_eq!(coarse(empty, 2), empty);
    }

    #[test]
    fn reduction_keeps_the_farthest_depth_of_each_block() {
        // 5 × 3, reversed Z: smaller is farther; a NaN reads as the farthest.
        let depth = [
            0.5,
            0.4,
            0.9,
            0.9,
            0.1, //
            0.6,
            0.7,
            0.8,
            f32::NAN,
            0.2, //
            0.3,
            0.9,
            0.9,
            0.9,
            0.9,
        ];
        let mut out = Vec::new();
        assert_eq!(reduce_farthest(&depth, 5, 3, 1, &mut out), (3, 2));
        assert_eq!(&out[..], &[0.4, f32::NEG_INFINITY, 0.1, 0.3, 0.9, 0.9]);
        assert_eq!(reduce_farthest(&depth, 5, 3, 2, &mut out), (2, 1));
        assert_eq!(&out[..], &[f32::NEG_INFINITY, 0.1]);
    }

    #[test]
    fn near_occluders_cull_on_the_first_frame_and_direct_frames_are_identical() {
        let (scene, view) = wall_scene();
        let reference = zbuffer_frame(&scene, &view);
        // One near occluder: the wall (the largest screen box).
        for params in [
            "",
            ",scale=1",
            ",scale=8,passes=2",
            ",hierarchy=flat,passes=2",
            ",occluders=both",
        ] {
            let mut r = crate::AlgoSpec::parse(&format!("nbuffer:near_max=1{params}"))
                .expect("every listed nbuffer spec parses")
                .build(scene.clone(), &RenderOptions::default())
                .expect("every listed nbuffer spec builds");
            let mut f = Frame::new(view.width(), view.height()).expect("a frame of the view's size");
            let s = r.render(&view, &mut f).expect("nbuffer renders the wall scene");
            assert!(f.same_visibility(&reference), "{params}");
            assert_eq!(
                s.counters.get("near_occluders"),
                1,
                "{params}: the wall is the near occluder"
            );
            assert!(s.rects_culled > 0, "{params}: nothing culled behind the wall");
            assert!(s.counters.get("triangles_saved") > 0, "{params}");
        }
        // A frame drawn directly (as after a frame whose culling did not pay) tests nothing
        // and draws the same frame; the run of direct frames ends with a culling frame.
        let no = NBufferOptions::default();
        let mut r = NBufferCulling::with_options(scene.clone(), &RenderOptions::default(), &no)
            .expect("the default nbuffer options build");
        r.direct.as_mut().expect("payoff is on by default").force(2, false);
        for i in 0..3 {
            let mut f = Frame::new(view.width(), view.height()).expect("a frame of the view's size");
            let s = r.render(&view, &mut f).expect("nbuffer renders the wall scene");
            assert!(f.same_visibility(&reference), "frame {i}");
            let direct = i < 2;
            assert_eq!(s.counters.get("payoff_direct"), u64::from(direct), "frame {i}");
            assert_eq!(s.rects_tested == 0, direct, "frame {i}");
        }
    }

    /// Seen from behind, the wall (the near occluder, the largest screen box) lies behind
    /// everything else and hides nothing: the first frame is screened and drawn directly,
    /// untested, the same frame; the next is not screened again.
    /// Without payoff the frame is tested. Seen from the front (the test above) it is culled.
    #[test]
    fn a_first_frame_whose_occluders_hide_nothing_is_drawn_directly() {
        let (scene, _) = wall_scene();
        let camera = Camera::look_at(Vec3::new(2.0, 1.5, -12.0), Vec3::new(2.0, 1.5, 0.0));
        let view = View::new(camera, 96, 64).expect("a view of the wall from behind");
        let reference = zbuffer_frame(&scene, &view);
        let frames = |spec: &str, n: usize| -> Vec<FrameStats> {
            let mut r = crate::AlgoSpec::parse(spec)
                .expect("the spec parses")
                .build(scene.clone(), &RenderOptions::default())
                .expect("nbuffer builds");
            (0..n)
                .map(|i| {
                    let mut f = Frame::new(view.width(), view.height()).expect("a frame of the view's size");
                    let s = r.render(&view, &mut f).expect("nbuffer renders the wall from behind");
                    assert!(f.same_visibility(&reference), "{spec}, frame {i}");
                    s
                })
                .collect()
        };
        let s = frames("nbuffer:near_max=1", 2);
        assert_eq!(s[0].counters.get("occluders_drawn"), 1);
        assert_eq!(s[0].counters.get("payoff_screened"), 1);
        assert_eq!(s[0].counters.get("payoff_direct"), 1);
        assert_eq!(s[0].rects_tested, 0, "no test run");
        // The next frame is not screened again. It is culled, or drawn directly when the first
        // (with its redraw) took at least MIN_ALLOWANCE_TIME and so started a run of direct
        // frames; a frame shorter than that starts none (a slow machine may take either way).
        assert_eq!(s[1].counters.get("payoff_screened"), 0);
        let direct = s[1].counters.get("payoff_direct") == 1;
        assert_eq!(
            s[1].rects_tested > 0,
            !direct,
            "the second frame tests or is drawn directly"
        );
        if s[0].total < crate::payoff::MIN_ALLOWANCE_TIME {
            assert!(!direct, "a first frame this short starts no run of direct frames");
        }
        let s = frames("nbuffer:near_max=1,payoff=off", 1);
        assert!(s[0].rects_tested > 0);
        assert_eq!(s[0].counters.get("payoff_screened"), 0);
    }

    /// With `occluders=visible` and payoff on, the first frame finds no occluder and is drawn
    /// directly; its visible objects are read back, so the next frame has occluders and culls.
    #[test]
    fn visible_occluders_come_from_a_frame_without_occluders() {
        let (scene, view) = wall_scene();
        let reference = zbuffer_frame(&scene, &view);
        let mut r = crate::AlgoSpec::parse("nbuffer:occluders=visible")
            .expect("the spec parses")
            .build(scene.clone(), &RenderOptions::default())
            .expect("nbuffer builds");
        let mut stats = Vec::new();
        for i in 0..2 {
            let mut f = Frame::new(view.width(), view.height()).expect("a frame of the view's size");
            stats.push(r.render(&view, &mut f).expect("nbuffer renders the wall"));
            assert!(f.same_visibility(&reference), "frame {i}");
        }
        assert_eq!(stats[0].counters.get("no_occluders"), 1);
        assert_eq!(stats[1].counters.get("no_occluders"), 0);
        assert!(stats[1].counters.get("occluders_drawn") > 0);
        assert!(stats[1].rects_culled > 0, "the wall, read back, hides the grids");
    }

    #[test]
    fn bad_options_are_named_errors() {
        let (scene, _) = wall_scene();
        for bad in [
            "scale=3",
            "scale=0",
            "passes=0",
            "passes=3",
            "near_area=1.5",
            "near_area=-0.1",
            "occluders=all",
            "payoff=maybe",
            "near_max=-1",
        ] {
            let key = bad.split('=').next().expect("split yields at least one piece");
            match crate::AlgoSpec::parse(&format!("nbuffer:{bad}"))
                .expect("bad values parse; build refuses them")
                .build(scene.clone(), &RenderOptions::default())
            {
                Err(RenderError::BadParameter(m)) => assert!(m.contains("nbuffer") && m.contains(key), "{bad}: {m}"),
                Err(e) => panic!("{bad}: {e}"),
                Ok(_) => panic!("{bad} was accepted"),
            }
        }
    }
}
