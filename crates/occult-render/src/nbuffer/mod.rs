//! N-buffer occlusion culling (`nbuffer`).
//!
//! # References
//! Décoret, *N-Buffers for efficient depth map query*, 2005 (`papers/n-buffers-decoret-2005.txt`):
//! - §3.1: occluders are the objects visible in the previous frame [BWPP04]; they are drawn,
//!   an N-buffer is built from the depth buffer (§2, [`occult_raster::NBuffer`], min variant
//!   = farthest depth in our reversed-Z), every object's screen box and nearest depth is
//!   tested with four lookups (Fig. 3 cover), and the survivors not drawn yet are drawn.
//! - §3.2: particle culling, [`particles`].
//! - §4.2 / Table 2: the same test over a hierarchy of bounding volumes (`hierarchy=bvh`) or
//!   over every object (`hierarchy=flat`): testing a node costs the same four lookups as
//!   testing one object, so a culled node saves all its objects' tests.
//!
//! # Objects
//! An object is a mesh instance of the scene DAG, or, for a mesh of more than `leaf`
//! triangles, a leaf of a median-split BVH over its triangles (so one terrain mesh is many
//! objects). Transforms are composed from the root exactly as `frustum` and `zbuffer` do and
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
//! # First frame
//! With no previous frame (and after a resolution change) the occluder set is empty: the
//! N-buffer of an empty depth buffer culls nothing, so the first frame is frustum culling.
//! Each frame's visible objects are read back from the item buffer (exact, not the set of
//! test survivors) and become the next frame's occluders.
//!
//! # Deviations
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
//! Per frame: drawing last frame's visible set, one N-buffer build (resolution only), 4 loads
//! per tested box (one when its rectangle is a single pixel, none when it covers no pixel centre), and
//! a pass over the item buffer. Not worth it when nearly everything is visible.

pub mod particles;
pub mod shadows;

use std::sync::Arc;
use std::time::Instant;

use occult_core::{Aabb, Affine3A, Containment, ItemId, NodeId, NodeKind, Scene, Vec3, View, NO_ITEM};
use occult_raster::{query_box_counted, Draw, DrawTriangles, Extremum, Frame, NBuffer, PixelRect, Rasterizer};
use occult_spatial::Bvh;

use crate::nodes::{per_node, triangle_boxes};
use crate::walk::{cull_bvh, test_box};
use crate::{AlgorithmInfo, FrameStats, ParamDoc, Phase, RenderError, RenderOptions, Renderer, Result};

/// Largest number of objects (mesh instances × triangle chunks) the renderer flattens.
pub const MAX_OBJECTS: u64 = 1 << 24;

/// Registry entry of [`NBufferCulling`].
pub static INFO: AlgorithmInfo = AlgorithmInfo {
    name: "nbuffer",
    summary: "N-buffer occlusion culling (Décoret 2005): last frame's visible objects as occluders, 4-lookup box tests",
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
            default: "4096",
            help: "triangles per object: meshes above this are split into BVH leaves (>= 1)",
        },
        ParamDoc {
            key: "group_leaf",
            default: "4",
            help: "objects per leaf of the hierarchy over objects (>= 1)",
        },
    ],
    counters: &[
        "occluders_drawn",
        "depth_comparisons",
        "nbuffer_lookups",
        "rect_pixels",
        "survivors_drawn",
    ],
    conservative: true,
    build: |scene, options, params| {
        let defaults = NBufferOptions::default();
        let no = NBufferOptions {
            hierarchy: params.choice("hierarchy", &["bvh", "flat"], "bvh")? == "bvh",
            four_square: params.choice("cover", &["four", "one"], "four")? == "four",
            query: params.choice("test", &["nbuffer", "query"], "nbuffer")? == "query",
            leaf_size: params.get("leaf", defaults.leaf_size)?,
            group_leaf_size: params.get("group_leaf", defaults.group_leaf_size)?,
        };
        Ok(Box::new(NBufferCulling::with_options(scene, options, &no)?))
    },
};

/// Tunables of [`NBufferCulling`].
#[derive(Clone, Debug, PartialEq, Eq)]
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
}

impl Default for NBufferOptions {
    fn default() -> Self {
        Self {
            hierarchy: true,
            four_square: true,
            query: false,
            leaf_size: 4096,
            group_leaf_size: 4,
        }
    }
}

impl NBufferOptions {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a zero leaf size.
    pub fn validate(&self) -> Result<()> {
        if self.leaf_size == 0 || self.group_leaf_size == 0 {
            return Err(RenderError::BadParameter(format!(
                "nbuffer: leaf={} and group_leaf={} must be at least 1",
                self.leaf_size, self.group_leaf_size
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
}

impl NBufferCulling {
    /// Flattens `scene` into objects and builds the hierarchy over them.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a zero leaf size or more than [`MAX_OBJECTS`]
    /// objects (checked before allocating them); raster configuration errors.
    pub fn with_options(scene: Arc<Scene>, options: &RenderOptions, no: &NBufferOptions) -> Result<Self> {
        no.validate()?;
        let raster = Rasterizer::new(options.raster.clone())?;
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
            let mut push = |object_bounds: Aabb, leaf_node: u32| {
                objects.push(Object {
                    world_from_object: *world_from_object,
                    bounds: widen(object_bounds.transformed(world_from_object)),
                    first_item,
                    mesh: mesh_id,
                    leaf_node,
                    instance,
                })
            };
            match (&mesh_bvhs[mesh_id.index()], &leaves[mesh_id.index()]) {
                (Some(bvh), Some(l)) => {
                    for &n in l {
                        push(bvh.nodes()[n as usize].bounds, n);
                    }
                }
                _ => push(scene.node(mesh_id).bounds(), u32::MAX),
            }
        });
        let hierarchy = no.hierarchy.then(|| {
            let boxes: Vec<Aabb> = objects.iter().map(|o| o.bounds).collect();
            Bvh::build(&boxes, no.group_leaf_size)
        });
        let n = objects.len();
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
        })
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
    clip_from_world: occult_core::Mat4,
    width: f64,
    height: f64,
}

impl BoxTest<'_> {
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

    /// True when the box is hidden; adds the depth comparisons made and the pixels of the
    /// tested rectangle to `tally`. Boxes reaching the near plane are never hidden and are
    /// not tested (in both modes, so both test the same boxes).
    fn hidden(&self, b: &Aabb, tally: &mut Tally) -> bool {
        let (rect, nearest) = match self.screen(b) {
            Screen::Empty => return true,
            Screen::Anywhere => return false,
            Screen::Rect(rect, nearest) => (rect, nearest),
        };
        tally.rect_pixels += rect.area();
        match self.against {
            Against::NBuffer(nbuffer, true) => {
                let (hidden, n) = nbuffer.occludes(rect, nearest);
                tally.comparisons += u64::from(n);
                hidden
            }
            Against::NBuffer(nbuffer, false) => {
                let q = nbuffer.query_one(rect);
                tally.comparisons += u64::from(q.lookups);
                q.lookups == 0 || nearest < q.depth
            }
            Against::Query(frame, view) => {
                // Deviation: the software occlusion query counts every pixel of the
                // silhouette (no early out), as a hardware query's sample count does.
                let q = query_box_counted(frame, view, &self.clip_from_world, b);
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
        let (start, _, mut stats) = crate::begin_frame(&mut self.raster, view, frame)?;
        if self.last_size != (view.width(), view.height()) {
            self.visible.fill(false);
            self.last_size = (view.width(), view.height());
        }
        let frustum = view.frustum(&Affine3A::IDENTITY);
        self.drawn.fill(false);

        // §3.1: draw last frame's visible objects (those still in the frustum) as occluders.
        let t = Instant::now();
        let mut occluders = Vec::new();
        for i in 0..self.objects.len() {
            if self.visible[i] {
                if test_box(&mut stats, &frustum, &self.objects[i].bounds) == Containment::Outside {
                    continue;
                }
                self.drawn[i] = true;
                occluders.push(i);
            }
        }
        let draws = draws_of(&self.scene, &self.objects, &self.mesh_bvhs, view, &mut occluders);
        stats.phases.add(Phase::Cull, t.elapsed());
        crate::rasterize(&mut self.raster, view, frame, &draws, &mut stats);
        drop(draws);
        stats.counters.add("occluders_drawn", occluders.len() as u64);

        // §2: the N-buffer of the occluders' depth (min variant: farthest depth); none for
        // occlusion queries, which read the depth buffer itself.
        let (w, h) = (view.width(), view.height());
        if !self.options.query {
            let t = Instant::now();
            let levels = NBuffer::default_level_count(w, h);
            let result = self.raster.install(|| match &mut self.nbuffer {
                Some(nb) => nb.rebuild(frame.depth(), w, h, levels),
                None => NBuffer::new(Extremum::Min, frame.depth(), w, h).map(|nb| {
                    self.nbuffer = Some(nb);
                }),
            });
            result?;
            stats.phases.add(Phase::DepthStructure, t.elapsed());
        }

        // §3.1: test every object (through the hierarchy or flat), keep the survivors.
        let t = Instant::now();
        let against = match &self.nbuffer {
            Some(nbuffer) if !self.options.query => Against::NBuffer(nbuffer, self.options.four_square),
            _ => Against::Query(&*frame, view),
        };
        let test = BoxTest {
            against,
            clip_from_world: view.clip_from_object(&Affine3A::IDENTITY),
            width: f64::from(w),
            height: f64::from(h),
        };
        let mut tally = Tally::default();
        let mut survivors = Vec::new();
        let objects = &self.objects;
        let drawn = &self.drawn;
        let mut test_object = |i: usize, inside: bool, stats: &mut FrameStats, tally: &mut Tally| {
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
            } else {
                survivors.push(i);
            }
        };
        match &self.hierarchy {
            Some(bvh) if !bvh.nodes().is_empty() => cull_bvh(&mut stats, bvh, &frustum, |stats, _, node, inside| {
                if node.is_leaf() {
                    for &i in &bvh.primitive_indices()[node.range()] {
                        test_object(i as usize, inside, stats, &mut tally);
                    }
                    return false;
                }
                // §4.2: an inner node is tested like an object; a hidden one hides its subtree.
                stats.rects_tested += 1;
                if test.hidden(&node.bounds, &mut tally) {
                    stats.rects_culled += 1;
                    return false;
                }
                true
            }),
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
                        match test.screen(&object.bounds) {
                            Screen::Empty => stats.rects_culled += 1,
                            Screen::Anywhere => survivors.push(i),
                            Screen::Rect(rect, nearest) => {
                                tally.rect_pixels += rect.area();
                                batch.push(i, rect, nearest);
                            }
                        }
                    }
                    tally.comparisons += batch.test(nbuffer)?;
                    for (&i, &hidden) in batch.objects.iter().zip(&batch.hidden) {
                        if hidden {
                            stats.rects_culled += 1;
                        } else {
                            survivors.push(i as usize);
                        }
                    }
                }
                _ => {
                    for i in 0..objects.len() {
                        test_object(i, false, &mut stats, &mut tally);
                    }
                }
            },
        }
        // Table 2: the depth comparisons of the tests (N-buffer lookups, or the pixels the
        // occlusion queries compared).
        stats.counters.add("depth_comparisons", tally.comparisons);
        if !self.options.query {
            stats.counters.add("nbuffer_lookups", tally.comparisons);
        }
        // The pixels of the tested boxes' screen rectangles (what a per-pixel test of the
        // rectangles, `query_rect`, would compare).
        stats.counters.add("rect_pixels", tally.rect_pixels);
        stats.counters.add("survivors_drawn", survivors.len() as u64);
        let draws = draws_of(&self.scene, &self.objects, &self.mesh_bvhs, view, &mut survivors);
        stats.phases.add(Phase::Cull, t.elapsed());
        crate::rasterize(&mut self.raster, view, frame, &draws, &mut stats);
        drop(draws);

        // The exactly visible objects become the next frame's occluders.
        let t = Instant::now();
        self.read_back_visible(frame);
        stats.phases.add(Phase::Other, t.elapsed());
        stats.total = start.elapsed();
        Ok(stats)
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
            + self.raster.memory_bytes()
    }
}
