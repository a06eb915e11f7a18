//! Local z-buffering: a near z-buffer pass plus lazy, selective, object-oriented ray casting
//! that finds a potentially visible list (PVL) for the rest of the scene.
//!
//! # References
//! Han & Zeiger, "The Local Z-Buffering Rendering" (`papers/local-z-buffering-han-zeiger.txt`):
//! - §II.A preprocessing: an octree per node of the scene DAG ([`occult_spatial::RayOctree`], the
//!   Akenine-Möller triangle–box test, max depth and max triangles per leaf); real-time steps
//!   1–5: hierarchical view-frustum culling collecting leaves, the partition plane, local
//!   rendering of `S_near` with the z-buffer, the unfinished pixels read back from the frame,
//!   rays from them.
//! - §II.B partition plane `z = z_clip`: static (a fraction of the frustum's depth over the
//!   scene) or dynamic (coarse ray casting from a uniform grid of pixels, mean first-hit
//!   distance), reused across frames while the camera moves little.
//! - §II naive ray casting (`mode=naive`): first hits shaded directly. Approximate (the ray's
//!   depth and coverage are not the rasterizer's): `is_conservative` is false in that mode.
//! - §III.A lazy ray casting: each ray records the leaves of its path up to its first hit; the
//!   union, without duplicates (a stamp per triangle), is the PVL, drawn with the z-buffer.
//! - §III.B selective lazy ray casting (`select=`): static local occluders (Octree-o: each
//!   leaf's list is sorted by area, its first `k` are the occluders), dynamic selection by
//!   visibility `|v·n|·area` against a base visibility per leaf (`base_cos` × mean area), and the
//!   hybrid (the `k` occluders filtered by visibility). A leaf whose occluders are missed is
//!   recorded whole and the ray goes on.
//! - §III.C object-oriented ray casting (`oor=on`): rays only from unfinished pixels inside
//!   the screen polygons (hull of the projected corners, found from the base corner plus offset
//!   vectors) of the leaves in the frustum behind the plane, with a done-mask so that no pixel
//!   is cast twice.
//! - §III.D coherence-based traversal (`coherence=on`): a ray first tests the leaf where its
//!   neighbour's ray ended, and that hit bounds its whole traversal.
//!
//! # Conservativeness (DESIGN invariant 2)
//! The frame is `S_near ∪ PVL` rasterized; it equals `zbuffer`'s when every pixel's winning
//! triangle is in that set. Three margins make it so against the rasterizer's own rules:
//! - A leaf is near when its box reaches nearer than `z_clip · 1.01`; a pixel is finished only
//!   when its near-pass depth is nearer than `z_clip`. Far triangles' fragments lie behind
//!   `1.01 · z_clip`, so they cannot win a finished pixel.
//! - Rays are cones of 1/8 pixel radius ([`occult_spatial::FatRay`]): a triangle that the
//!   rasterizer's snapped coverage gives a pixel lies within the cone of its centre.
//! - A ray ends only at a *robust* hit (`cast.rs`): the pixel centre lies at least 1/32 pixel
//!   inside every projected edge (computed from the rasterizer's `clip_from_object`), the corners
//!   well in front of the near plane, facing right if back faces are culled. It records every
//!   leaf it enters up to `t_hit · (1 + 2·10⁻³)`, so the pixel's winner, at most as far, is in
//!   the PVL even when coplanar or near-coplanar triangles tie with the hit.
//!
//! # Deviations
//! - Instanced scenes are not flattened: an octree per mesh (over its triangles) and per group
//!   (over its instances' boxes); rays descend through instances in their object space. Memory
//!   is linear in unique geometry. PVL entries are `(instance, leaf)`; triangles are
//!   deduplicated per instance with a stamp per unique triangle.
//! - Octree boxes are octants of the node's bounds (not a cube).
//! - The mesh octrees' leaf size (`leaf=auto`, the default; [`LzbOptions::leaf_size`]): the
//!   paper's 150 where the rays walk the octree (`caster=octree`); with `caster=bvh` (the
//!   default), the scene's triangle instances / 16,384, within 150..=16,384: a frame's work
//!   per leaf in view (the walk, the split, the polygons, the near pass's units) stays bounded
//!   on scenes of tens of millions of triangles (docs/lzb.md).
//! - The static plane's fraction is of the depth over which the scene lies in the frustum
//!   (`near` to the farther of the scene bounds and the far plane), not of `[near, far]`:
//!   with far planes far beyond the scene the paper's 15–30 % would hold all of it.
//! - The dynamic selection uses `|v·n|` (the rasterizer draws both faces unless back faces are
//!   culled).
//! - OOR marks the done-mask object by object, then casts the marked pixels in tiles over
//!   threads (the paper casts while marking, on one processor).
//! - Coherence bounds the traversal by the neighbour's hit instead of starting below the root
//!   (see [`occult_spatial::raycast`]).
//! - The PVL goes to this crate's software rasterizer, not a GPU.
//! - Addition, the partition plane by a cost model (`plane=cost`, the default in lazy mode;
//!   [`cost_plane`]): the coarse rays' first-hit distances, and the least view distance and
//!   triangles of every leaf in the frustum (collected by step 1 before the split), give for
//!   each candidate plane the triangles drawn near, the pixels left to the rays, the far leaves
//!   and their expected PVL; the plane whose frame would cost least at last frame's measured
//!   rates (per triangle, per ray, per far leaf, the PVL's share of the far triangles) wins.
//!   Where rays cost more than the triangles they would spare, that is every leaf near: the
//!   frame is a z-buffer frame. A mesh instance all of whose leaves are near is drawn whole
//!   (its vertices shared), not by leaf lists. The paper's mean-hit plane is `plane=dynamic`.
//! - Addition, payoff (`payoff=on`, lazy mode only; [`crate::payoff`], [`crate::direct`]): the
//!   rays are cast in waves, and a frame that has spent a direct frame's time and whose rays
//!   left, at their pace so far, would take longer than another is given up: the rest of its
//!   near set and its far leaves are drawn directly, untested, keeping what it drew; runs of frames are drawn directly while lzb frames lose to direct
//!   ones, probed between runs. DESIGN's invariant 5 (never slower than brute force) asks it of
//!   every conservative renderer. Counters `payoff_direct`, `payoff_stopped`; `payoff=off`
//!   measures the paper's algorithm alone.
//! - The rays' structure in a mesh (`caster=bvh`, the default; `caster=octree`, the paper's,
//!   whose one-at-a-time cone rays measured faster when they record leaves): an 8-wide BVH per
//!   unique mesh
//!   ([`occult_spatial::RayBvh`]: binned SAH, one reference per triangle, leaves of up to
//!   `bvh_leaf` triangles stored contiguously), not the paper's octree, which stays for the
//!   frustum walk, the near/far split, the object-oriented polygons and the near pass. Its
//!   8 children's boxes are tested in SIMD lanes, each grown by the cone's radius at its far
//!   side as the octree's leaves are ([`occult_spatial::traverse_bvh`]), nearest first. The PVL
//!   is made of the BVH leaves on the ray paths (a few triangles each: near triangle-exact);
//!   a BVH leaf whose box lies wholly nearer than the near limit is not recorded (every
//!   octree leaf holding a part of its triangles is near: the near pass draws them or finds
//!   them hidden). §III.D's start is the BVH subtree two levels above the neighbour's hit
//!   leaf. `caster=octree` casts through the octree as the paper does.
//! - Naive rays in packets (`packets=on`, the default with `caster=bvh`): the
//!   rays of an 8×8 tile walk each mesh's BVH together ([`occult_spatial::traverse_bvh_packet`]:
//!   each ray tested as alone at every node it reaches, a leaf's triangles read once for its
//!   rays) and a group's octree as one cone that holds them (`Caster::cast_packet`). The same
//!   hits as one at a time, but for ties within rounding.
//! - `pvl=hits` (the default in lazy mode unless `caster=octree`; not in the paper): lazy rays
//!   in packets of an 8×8 tile, each a cone of 1/64 pixel bounded by its first robust hit,
//!   record the triangles their cone may touch before the bound
//!   ([`occult_spatial::ShearedRay::candidates8`], `Caster::cast_packet_hits`) instead of the
//!   leaves they enter: triangle-exact. Conservative because the pixel's winner has a point
//!   within the cone, nearer than the bound. `select=`, `k=`, `base_cos=` and `coherence=`
//!   (rays that record leaves, one at a time) are refused with it.
//! - `pvl=triangles` (an option): the ray's record keeps, of each leaf on the path, only the
//!   triangles whose box the ray's cone enters before the bound. Conservative for the same
//!   reason as the leaves: the pixel's winner lies within the cone, nearer than the bound.
//!   `pvl=leaves` (the default with `caster=octree`): the paper's leaves.

mod cast;
mod leaves;
mod near;
mod oor;
mod options;
mod owned;
mod plane;
pub mod shared;

pub use options::{
    auto_leaf, CasterKind, LzbOptions, Mode, Plane, Pvl, Selection, AUTO_LEAF_BUDGET, AUTO_LEAF_MAX, INFO, PAPER_LEAF,
};
pub use plane::cost_plane;

use std::sync::Arc;
use std::time::{Duration, Instant};

use occult_core::{Aabb, Affine3A, Camera, Containment, Frustum, ItemId, Mat4, NodeKind, Scene, Vec3, Vec4, View};
use occult_raster::{Draw, DrawTriangles, Frame, PixelRect, PyramidCounts, Rasterizer, ZPyramid};
use occult_spatial::{RayBvh, RayBvhConfig, RayBvhError, RayOctree, RayOctreeConfig, RayOctreeError};
use rayon::prelude::*;

/// The least view distance of box `b` (object space; `w_row` the clip-w row of its
/// `clip_from_object`), a bound from below: what [`FrameCtx::is_near`] compares with the limit.
#[inline]
fn near_distance(w_row: Vec4, b: &Aabb) -> f32 {
    let n = w_row.truncate();
    n.dot(b.center()) + w_row.w - n.abs().dot(b.half_extent())
}

/// Rasterization cost of a triangle, wall ns, before `plane=cost` measured one.
const PRIOR_NS_PER_TRIANGLE: f64 = 20.0;
/// Triangles a frame must draw for `plane=cost` to learn the cost of a triangle from it.
const MIN_RATE_TRIANGLES: u64 = 10_000;
/// Cost of a ray, wall ns, before `plane=cost` measured one.
const PRIOR_NS_PER_RAY: f64 = 1000.0;
/// Share of the far leaves' triangles the rays' PVL holds, before `plane=cost` measured it.
const PRIOR_PVL_SHARE: f64 = 0.5;
/// Wall ns per far leaf outside rays and rasterization (its object-oriented polygon over the
/// unfinished pixels, its part of the PVL's assembly), before `plane=cost` measured it.
const PRIOR_NS_PER_FAR_LEAF: f64 = 500.0;

/// Pixels cast between two checks of the payoff balance (`payoff=on`): a few milliseconds of
/// rays at the slowest rates measured, so a frame given up overshoots little.
const RAY_WAVE: usize = 4096;

/// Bands of rows per thread that §III.C's done-mask is marked in at once ([`oor::mark`]):
/// more than one, so that a thread done with a band of few far leaves takes another.
const OOR_BANDS_PER_THREAD: usize = 2;

/// Triangles of the near pass's first batch (`near_cull=on`), drawn untested: the nearest
/// units, occluders of the rest.
const NEAR_FIRST_BATCH: usize = 4096;
/// Triangle references of a unit of the near pass's tests (`near_cull=on`): consecutive near
/// leaves of a mesh instance, up to this many, are tested as one box (within groups,
/// [`NEAR_GROUP`]; smaller units submit fewer triangles for more tests, docs/lzb.md).
const NEAR_UNIT: u32 = 64;
/// Units of a group of the near pass's tests (`near_cull=on`): consecutive units of an
/// instance, up to this many, are first tested as one box, and each only where that box is
/// not hidden.
const NEAR_GROUP: usize = 16;
/// Largest batch of the near pass: batches double up to it, each followed by a pyramid update
/// (of the batch's screen rectangle: on a street, most of the screen; a near set of millions
/// of triangles in batches of 65,536 spent more in updates than in drawing).
const NEAR_MAX_BATCH: usize = 1 << 18;

/// `near_temporal` reads one pixel in this many, in x and in y, of a finished frame's items
/// for the leaves that showed a pixel: a leaf missed is only tested, and a quarter of the
/// reads of a stride of 2 found the same first batches (docs/lzb.md).
const VISIBLE_STRIDE: usize = 8;

/// Words of a frame's drawn-leaf bits ([`owned::DrawnLeaves`]) a leaf in view may add to their
/// budget, beyond [`DRAWN_MIN_WORDS`]: the bits stay within a few times the frame's own lists.
const DRAWN_WORDS_PER_LEAF: usize = 4;
/// Words of the drawn-leaf bits any frame may hold (512 KiB).
const DRAWN_MIN_WORDS: usize = 1 << 16;

/// Pixels one task casts (one [`Caster`], so one coherence chain).
const CHUNK: usize = 256;

/// Deepest octree `lzb` accepts (its documented `depth` range is 0..=24): an `f32` octant of
/// the node's bounds halved more often than its mantissa has bits no longer splits it.
const MAX_DEPTH: u32 = 24;

use crate::direct::DirectFrames;
use crate::hzb::boxtest::{screen_rect, Occlusion};
use crate::payoff::{FramePayoff, Payoff, MIN_ALLOWANCE_TIME};
use crate::walk::{NodeAt, SceneWalk, Visitor};
use crate::{FrameStats, Phase, RenderError, RenderOptions, Renderer, Result};
use cast::{row_w, Caster, InstanceRec};
use leaves::Walk;

/// The acceleration structure of one DAG node.
pub(crate) enum Accel {
    /// No triangle below.
    Empty,
    /// A mesh: octree over its triangles.
    Mesh {
        /// Leaves sorted by triangle area, largest first (Octree-o).
        octree: RayOctree,
        /// Per leaf-list entry (parallel to `octree.primitives()`): the triangle's corners and
        /// area-scaled normal, so that a ray reads a leaf's triangles contiguously.
        refs: Vec<RefTriangle>,
        /// Per octree node (leaves only meaningful): base visibility `base_cos × mean area`.
        leaf_base: Vec<f32>,
        /// Its non-empty leaves (all of them near: the mesh is drawn whole).
        leaves: u32,
        /// The near pass's units of an instance all of whose leaves are near ([`near::near_chunks`]).
        chunks: Vec<near::NearChunk>,
        /// Per triangle: the leaf that owns it, one of those that list it (`u32::MAX`: none;
        /// [`owned`]), so that a pixel's item names a leaf (`near_temporal`).
        leaf_of: Vec<u32>,
        /// The leaves' own triangles as clusters, and those they borrow ([`owned`]): how the
        /// near pass draws leaves.
        clusters: Box<owned::LeafClusters>,
        /// What the rays walk with `caster=bvh`.
        bvh: Option<MeshBvh>,
    },
    /// A group: octree over its instances' boxes.
    Group {
        octree: RayOctree,
        /// Instance boxes in the group's space.
        bounds: Vec<Aabb>,
        /// Inverse placements.
        child_from_parent: Vec<Affine3A>,
        /// Bound on how much each inverse placement stretches lengths.
        stretch: Vec<f32>,
    },
}

/// Triangles `ids` of mesh `m` as a ray caster reads them (`normals`: area-scaled).
/// On huge pages: rays read them at scattered places.
fn leaf_triangles(m: &occult_core::Mesh, normals: &[Vec3], ids: &[u32]) -> Vec<RefTriangle> {
    let mut tris = occult_core::memory::huge_page_vec(ids.len());
    tris.extend(ids.iter().map(|&t| RefTriangle {
        corners: m.triangle_positions(t as usize),
        normal: normals[t as usize],
    }));
    tris
}

/// A mesh's ray BVH (`caster=bvh`) with its triangles in leaf order.
pub(crate) struct MeshBvh {
    /// Leaves sorted by triangle area, largest first (as the octree's, for `select=`).
    bvh: RayBvh,
}

impl MeshBvh {
    /// The BVH of mesh `m`, each leaf sorted by area, with its triangles (`normals`: area-scaled).
    fn build(m: &occult_core::Mesh, normals: &[Vec3], leaf: usize) -> std::result::Result<Self, RayBvhError> {
        let mut bvh = RayBvh::build_triangles(m.positions(), m.triangles(), RayBvhConfig { max_leaf_size: leaf })?;
        bvh.sort_leaves_by_key_descending(|t| normals[t as usize].length());
        let tris = leaf_triangles(m, normals, bvh.triangles());
        bvh.attach_triangles(tris);
        Ok(Self { bvh })
    }

    fn memory_bytes(&self) -> usize {
        self.bvh.memory_bytes()
    }
}

impl Accel {
    fn memory_bytes(&self) -> usize {
        match self {
            Accel::Empty => 0,
            Accel::Mesh {
                octree,
                refs,
                leaf_base,
                leaf_of,
                bvh,
                chunks,
                clusters,
                ..
            } => {
                octree.memory_bytes()
                    + clusters.memory_bytes()
                    + chunks.capacity() * std::mem::size_of::<near::NearChunk>()
                    + refs.capacity() * std::mem::size_of::<RefTriangle>()
                    + (leaf_base.capacity() + leaf_of.capacity()) * 4
                    + bvh.as_ref().map_or(0, MeshBvh::memory_bytes)
            }
            Accel::Group {
                octree,
                bounds,
                child_from_parent,
                stretch,
            } => {
                octree.memory_bytes()
                    + bounds.capacity() * 24
                    + child_from_parent.capacity() * 48
                    + stretch.capacity() * 4
            }
        }
    }
}

/// A leaf-list entry's triangle (object space), stored in leaf order for the ray caster.
pub(crate) use occult_spatial::LeafTriangle as RefTriangle;

/// The partition plane of a frame, or what it is to be chosen from.
enum PlaneChoice {
    /// At this view distance.
    At(f32),
    /// `plane=cost`: chosen by [`cost_plane`] from these coarse first hits once the leaves in
    /// the frustum are known.
    Cost(Vec<Option<f32>>),
}

/// A partition plane kept for reuse (§II.B).
struct PlaneCache {
    camera: Camera,
    z_clip: f32,
    frames: u32,
}

/// The local z-buffering renderer.
pub struct Lzb {
    scene: Arc<Scene>,
    raster: Rasterizer,
    opts: LzbOptions,
    accel: Vec<Accel>,
    /// Per mesh node: a stamp per triangle (PVL without duplicates).
    stamps: Vec<Vec<u32>>,
    /// The leaves the frame drew, per instance ([`owned`]).
    drawn: owned::DrawnLeaves,
    stamp: u32,
    plane_cache: Option<PlaneCache>,
    build_time: Duration,
    /// Most triangles per mesh octree leaf ([`LzbOptions::leaf_size`]).
    leaf_size: usize,
    cull_backfaces: bool,
    /// What the rays' balance learned from earlier frames ([`crate::payoff`]).
    payoff: Payoff,
    /// Frames drawn directly where the rays do not pay (`payoff=on`).
    direct: Option<DirectFrames>,
    /// Octrees built shallower than asked, to fit their reference budget.
    shallower_octrees: usize,
    /// The near pass's depth pyramid (`near_cull=on`), made at the frame's size when first
    /// needed.
    pyramid: Option<ZPyramid>,
    /// The leaves that showed a pixel in the last frame, as (instance's first item, leaf),
    /// sorted (`near_temporal`): the near pass draws them first.
    near_visible: Vec<(ItemId, u32)>,
    /// The near pass's lists, kept across frames.
    near_scratch: near::NearScratch,
    /// A frame's lists of instances and leaves, kept across frames.
    lists: FrameLists,
    /// Wall time of a rasterized triangle and of a ray, last measured (`plane=cost`).
    ns_per_triangle: f64,
    ns_per_ray: f64,
    /// The triangles last frame's PVL held per triangle reference of the far leaves
    /// (`plane=cost`).
    pvl_share: f64,
    /// The triangles the near pass last drew per triangle reference of the near leaves
    /// (`plane=cost`; 1 without `near_cull`).
    near_share: f64,
    /// Wall ns per far leaf outside rays and rasterization, last measured (`plane=cost`).
    ns_per_far_leaf: f64,
}

/// An octree built by `build` with `config`, or, when it would hold more references than its
/// budget ([`RayOctreeError::TooLarge`]: on real models, large instances overlapping many
/// cells at every level), the deepest shallower one that fits: its leaves hold more, rays test
/// more of them, frames are the same. True in the second case. Each failed try stops at the
/// budget, a bounded amount of work.
///
/// # Errors
/// The build's other errors, or [`RayOctreeError::TooLarge`] when even the root alone exceeds
/// the budget.
fn fit_budget(
    config: RayOctreeConfig,
    build: impl Fn(RayOctreeConfig) -> std::result::Result<RayOctree, RayOctreeError>,
) -> std::result::Result<(RayOctree, bool), RayOctreeError> {
    let mut c = config;
    loop {
        match build(c) {
            Ok(tree) => return Ok((tree, c.max_depth < config.max_depth)),
            Err(RayOctreeError::TooLarge(_)) if c.max_depth > 0 => c.max_depth -= 1,
            Err(e) => return Err(e),
        }
    }
}

/// Per-frame constants shared by the walk and the rays.
pub(crate) struct FrameCtx {
    view: View,
    eye: Vec3,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
    near: f32,
    far: f32,
    width: f64,
    height: f64,
    /// Cone radius per unit of view distance (1/8 pixel).
    spread: f32,
    cull_backfaces: bool,
    /// A box reaching nearer than this view distance is near (`z_clip · 1.01`).
    near_limit: f32,
}

/// How much nearer than the plane a leaf must reach to count as near (see the module doc).
const NEAR_MARGIN: f32 = 0.01;

impl FrameCtx {
    fn new(view: &View, cull_backfaces: bool) -> Self {
        let v = view.view_from_world();
        let right = Vec3::new(v.x_axis.x, v.y_axis.x, v.z_axis.x);
        let up = Vec3::new(v.x_axis.y, v.y_axis.y, v.z_axis.y);
        let forward = -Vec3::new(v.x_axis.z, v.y_axis.z, v.z_axis.z);
        let p = view.clip_from_view();
        let (sx, sy) = (p.x_axis.x, p.y_axis.y);
        let (w, h) = (view.width() as f32, view.height() as f32);
        let pixel = (2.0 / (sx * w)).max(2.0 / (sy * h));
        Self {
            view: *view,
            eye: view.camera().eye,
            right: right / sx,
            up: up / sy,
            forward,
            near: view.camera().near,
            far: view.camera().far,
            width: w as f64,
            height: h as f64,
            spread: pixel * 0.125,
            cull_backfaces,
            near_limit: 0.0,
        }
    }

    /// Direction of the ray through screen point `(px, py)` (pixels, y down), scaled so that
    /// its parameter is the view distance.
    #[inline]
    fn pixel_direction(&self, px: f32, py: f32) -> Vec3 {
        let nx = px / self.width as f32 * 2.0 - 1.0;
        let ny = 1.0 - py / self.height as f32 * 2.0;
        self.forward + self.right * nx + self.up * ny
    }

    /// True when box `b` (object space, `w_row` the clip-w row of its `clip_from_object`)
    /// reaches nearer than the near limit: its triangles are drawn by the near pass.
    #[inline]
    fn is_near(&self, w_row: Vec4, b: &Aabb) -> bool {
        near_distance(w_row, b) < self.near_limit
    }

    /// True when all of box `b` lies nearer than the near limit: every octree leaf holding a
    /// part of a triangle inside it reaches nearer than the limit, so the near pass draws that
    /// triangle wherever it is in the frustum (or finds it hidden).
    #[inline]
    fn is_wholly_near(&self, w_row: Vec4, b: &Aabb) -> bool {
        let n = w_row.truncate();
        n.dot(b.center()) + w_row.w + n.abs().dot(b.half_extent()) < self.near_limit
    }
}

impl Lzb {
    /// Builds the octrees of `scene` (§II.A).
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for bad options or an octree over its reference budget
    /// even at depth 0 (deeper ones are built shallower, [`Lzb::shallower_octrees`]);
    /// raster configuration errors.
    pub fn new(scene: Arc<Scene>, options: &RenderOptions, opts: &LzbOptions) -> Result<Self> {
        opts.check()?;
        let start = Instant::now();
        let raster = crate::scene_rasterizer(&scene, options)?;
        let leaf_size = opts.leaf_size(&scene);
        let mesh_cfg = RayOctreeConfig {
            max_depth: opts.depth,
            max_leaf_size: leaf_size,
        };
        let group_cfg = RayOctreeConfig {
            max_depth: opts.depth,
            max_leaf_size: opts.group_leaf,
        };
        let base_cos = opts.base_cos;
        let built: Vec<Result<(Accel, bool)>> = raster.install(|| {
            scene
                .nodes()
                .par_iter()
                .map(|node| {
                    let err = |e: RayOctreeError| {
                        RenderError::BadParameter(format!("lzb: octree of node '{}': {e}", node.name()))
                    };
                    if node.item_count() == 0 {
                        return Ok((Accel::Empty, false));
                    }
                    Ok(match node.kind() {
                        NodeKind::Mesh(m) => {
                            let (mut octree, shallower) = fit_budget(mesh_cfg, |c| {
                                RayOctree::build_triangles(m.positions(), m.triangles(), c)
                            })
                            .map_err(err)?;
                            let normals: Vec<Vec3> = (0..m.triangle_count())
                                .map(|t| {
                                    let [a, b, c] = m.triangle_positions(t);
                                    (b - a).cross(c - a) * 0.5
                                })
                                .collect();
                            octree.sort_leaves_by_key_descending(|t| normals[t as usize].length());
                            let leaf_base = octree
                                .nodes()
                                .iter()
                                .map(|n| {
                                    if !n.is_leaf() || n.count == 0 {
                                        return 0.0;
                                    }
                                    let list = &octree.primitives()[n.range()];
                                    let sum: f32 = list.iter().map(|&t| normals[t as usize].length()).sum();
                                    base_cos * sum / list.len() as f32
                                })
                                .collect();
                            // Leaves stand for their tight boxes (the triangles' bounds clipped
                            // to the octant, grown as the overlap test grows it): every point of
                            // a triangle inside the leaf lies in it, so it serves every test
                            // (near/far, rays, OOR).
                            octree.tighten_leaves(|n, list| {
                                let b = n.bounds;
                                let grow = Vec3::splat(
                                    b.size().max_element() * 2e-5 + b.min.abs().max(b.max.abs()).max_element() * 2e-6,
                                );
                                list.iter()
                                    .fold(Aabb::EMPTY, |a, &t| {
                                        a.union(Aabb::from_points(m.triangle_positions(t as usize)))
                                    })
                                    .intersection(Aabb::new(b.min - grow, b.max + grow))
                            });
                            let refs = leaf_triangles(m, &normals, octree.primitives());
                            let leaf_of = owned::owners(&octree, m.triangle_count())?;
                            let clusters = Box::new(owned::LeafClusters::build(m, &octree, &leaf_of)?);
                            let bvh = match opts.caster {
                                CasterKind::Bvh => Some(MeshBvh::build(m, &normals, opts.bvh_leaf).map_err(|e| {
                                    RenderError::BadParameter(format!("lzb: BVH of node '{}': {e}", node.name()))
                                })?),
                                CasterKind::Octree => None,
                            };
                            (
                                Accel::Mesh {
                                    leaves: octree.nodes().iter().filter(|n| n.is_leaf() && n.count > 0).count() as u32,
                                    chunks: if opts.near_cull {
                                        near::near_chunks(&octree, clusters.owned_counts())
                                    } else {
                                        Vec::new()
                                    },
                                    octree,
                                    refs,
                                    leaf_base,
                                    leaf_of,
                                    clusters,
                                    bvh,
                                },
                                shallower,
                            )
                        }
                        NodeKind::Group(instances) => {
                            let bounds: Vec<Aabb> = instances
                                .iter()
                                .map(|i| {
                                    let child = scene.node(i.child);
                                    if child.item_count() == 0 {
                                        Aabb::EMPTY
                                    } else {
                                        child.bounds().transformed(&i.parent_from_child)
                                    }
                                })
                                .collect();
                            let (octree, shallower) =
                                fit_budget(group_cfg, |c| RayOctree::build_boxes(&bounds, c)).map_err(err)?;
                            let child_from_parent: Vec<Affine3A> =
                                instances.iter().map(|i| i.parent_from_child.inverse()).collect();
                            let stretch = child_from_parent
                                .iter()
                                .map(|m| {
                                    // ‖A‖₂ ≤ √(‖A‖₁‖A‖∞), with a little slack for rounding.
                                    let a = m.matrix3;
                                    let cols = [a.x_axis.abs(), a.y_axis.abs(), a.z_axis.abs()];
                                    let norm1 = cols.iter().map(|c| c.x + c.y + c.z).fold(0.0, f32::max);
                                    let rows = cols[0] + cols[1] + cols[2];
                                    (norm1 * rows.max_element()).sqrt() * 1.001
                                })
                                .collect();
                            (
                                Accel::Group {
                                    octree,
                                    bounds,
                                    child_from_parent,
                                    stretch,
                                },
                                shallower,
                            )
                        }
                    })
                })
                .collect()
        });
        let built = built.into_iter().collect::<Result<Vec<_>>>()?;
        let shallower_octrees = built.iter().filter(|(_, s)| *s).count();
        let accel: Vec<Accel> = built.into_iter().map(|(a, _)| a).collect();
        let stamps = scene
            .nodes()
            .iter()
            .map(|n| vec![0u32; n.mesh().map_or(0, |m| m.triangle_count())])
            .collect();

        let direct = match opts.payoff {
            true => Some(DirectFrames::new(scene.clone(), &raster)?.judging_first_by_time()),
            false => None,
        };
        Ok(Self {
            cull_backfaces: options.raster.cull_backfaces,
            payoff: Payoff::new(opts.payoff, scene.item_count()),
            scene,
            raster,
            opts: opts.clone(),
            accel,
            stamps,
            drawn: owned::DrawnLeaves::default(),
            stamp: 0,
            plane_cache: None,
            direct,
            shallower_octrees,
            ns_per_triangle: PRIOR_NS_PER_TRIANGLE,
            ns_per_ray: PRIOR_NS_PER_RAY,
            pvl_share: PRIOR_PVL_SHARE,
            near_share: 1.0,
            ns_per_far_leaf: PRIOR_NS_PER_FAR_LEAF,
            pyramid: None,
            near_visible: Vec::new(),
            near_scratch: near::NearScratch::default(),
            lists: FrameLists::default(),
            build_time: start.elapsed(),
            leaf_size,
        })
    }

    /// Most triangles per mesh octree leaf, as `leaf` (or `auto`) chose for the scene
    /// ([`LzbOptions::leaf_size`]; counter `octree_leaf`).
    pub fn leaf_size(&self) -> usize {
        self.leaf_size
    }

    /// Preprocessing time (octree builds, §II.A).
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Octrees built shallower than `depth` to stay within their reference budget
    /// ([`fit_budget`]).
    pub fn shallower_octrees(&self) -> usize {
        self.shallower_octrees
    }

    /// §II.B: the partition plane's view distance, or (`plane=cost`, not reused) the coarse
    /// rays' first-hit distances from which it is chosen once the leaves are known.
    fn partition_plane(&mut self, ctx: &FrameCtx, stats: &mut FrameStats) -> PlaneChoice {
        let near = ctx.near;
        if self.opts.plane == Plane::Static {
            let clip = ctx.view.clip_from_world();
            let w = row_w(&clip);
            let extent = self
                .scene
                .bounds()
                .corners()
                .iter()
                .map(|c| w.dot(c.extend(1.0)))
                .fold(near, f32::max)
                .min(ctx.far);
            return PlaneChoice::At(near + self.opts.plane_fraction * (extent - near));
        }
        let cam = *ctx.view.camera();
        if let Some(c) = &mut self.plane_cache {
            // Reuse while the eye moved less than 5 % of the plane distance and the view
            // direction turned less than ~5°.
            let moved = (cam.eye - c.camera.eye).length();
            let turned = cam.direction().dot(c.camera.direction());
            if c.frames < self.opts.plane_reuse
                && moved < 0.05 * c.z_clip
                && turned > 0.996
                && cam.near == c.camera.near
                && cam.far == c.camera.far
                && cam.fov_y_deg == c.camera.fov_y_deg
            {
                c.frames += 1;
                stats.counters.add("plane_reused", 1);
                return PlaneChoice::At(c.z_clip.clamp(near, ctx.far));
            }
        }
        let t = Instant::now();
        let n = self.opts.coarse_rays as f64;
        let gx = ((n * ctx.width / ctx.height).sqrt().ceil() as u32).clamp(1, ctx.view.width());
        let gy = ((n / gx as f64).ceil() as u32).clamp(1, ctx.view.height());
        let mut caster = Caster::new(self, ctx, true);
        let mut distances = Vec::with_capacity((gx * gy) as usize);
        for j in 0..gy {
            for i in 0..gx {
                let x = ((i as f64 + 0.5) / gx as f64 * ctx.width) as u32;
                let y = ((j as f64 + 0.5) / gy as f64 * ctx.height) as u32;
                distances.push(caster.cast(x, y).map(|(t, _)| t));
            }
        }
        stats.counters.add("coarse_rays", caster.rays);
        stats.nodes_visited += caster.counters.nodes_visited;
        stats.phases.add(Phase::Rays, t.elapsed());
        if self.opts.plane == Plane::Cost {
            return PlaneChoice::Cost(distances);
        }
        let (sum, hits) = distances
            .iter()
            .flatten()
            .fold((0f64, 0u32), |(s, n), &t| (s + t as f64, n + 1));
        // No hit: nothing to draw near; every pixel goes to the rays.
        let z_clip = if hits == 0 {
            near
        } else {
            ((sum / hits as f64) as f32).clamp(near, ctx.far)
        };
        self.remember_plane(cam, z_clip);
        PlaneChoice::At(z_clip)
    }

    /// Keeps `z_clip`, chosen for `camera`, for reuse (§II.B).
    fn remember_plane(&mut self, camera: Camera, z_clip: f32) {
        self.plane_cache = Some(PlaneCache {
            camera,
            z_clip,
            frames: 1,
        });
    }

    /// Reserves `n` stamps no triangle holds yet and returns the first (the stamps are reset
    /// when they would run out).
    fn reserve_stamps(&mut self, n: u32) -> u32 {
        if self.stamp >= u32::MAX - n {
            self.stamps.iter_mut().for_each(|s| s.fill(0));
            self.stamp = 0;
        }
        let first = self.stamp + 1;
        self.stamp += n;
        first
    }

    /// Builds index lists for `(key, leaf)` pairs grouped by key (consecutive), one draw per
    /// instance, each triangle once (stamps); `entries` says what the pairs' leaves are.
    /// `stamps_of`: the stamp of each group, reserved
    /// by the caller ([`Lzb::reserve_stamps`]) so that several calls skip what earlier ones
    /// listed for the same instance; `None`: a fresh stamp per group.
    fn emit(
        &mut self,
        groups: &[(InstanceRec, ItemId, std::ops::Range<usize>)],
        leaves: &[u32],
        pool: &mut Vec<u32>,
        entries: Entries,
        stamps_of: Option<&[u32]>,
    ) -> Vec<(InstanceRec, ItemId, std::ops::Range<usize>)> {
        let mut out = Vec::with_capacity(groups.len());
        for (g, (rec, first_item, range)) in groups.iter().enumerate() {
            let stamp = match stamps_of {
                Some(s) => s[g],
                None => self.reserve_stamps(1),
            };
            let Accel::Mesh { octree, bvh, .. } = &self.accel[rec.node.index()] else {
                continue;
            };
            let stamps = &mut self.stamps[rec.node.index()];
            let start = pool.len();
            for &leaf in &leaves[range.clone()] {
                let one = [leaf];
                let list = match (entries, bvh) {
                    (Entries::Triangles, _) => &one[..],
                    (Entries::BvhLeaves, Some(b)) => &b.bvh.triangles()[RayBvh::leaf_range(leaf)],
                    _ => octree.leaf_primitives(leaf),
                };
                for &t in list {
                    if stamps[t as usize] != stamp {
                        stamps[t as usize] = stamp;
                        pool.push(t);
                    }
                }
            }
            if pool.len() > start {
                out.push((*rec, *first_item, start..pool.len()));
            }
        }
        out
    }
}

/// What the `(instance, leaf)` pairs given to [`Lzb::emit`] name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Entries {
    /// Octree leaves.
    OctreeLeaves,
    /// BVH leaf codes (`caster=bvh`).
    BvhLeaves,
    /// Triangles.
    Triangles,
}

/// Consecutive units of an instance tested as one box before each of them (`near_cull=on`).
struct NearGroup {
    /// The least view distance of its units.
    distance: f32,
    /// Its instance.
    inst: u32,
    /// Its units: a range of the units (of those in the order they were built, then of those
    /// sorted group by group).
    units: std::ops::Range<u32>,
    /// The triangles its units' leaves own ([`owned`]).
    owned: u64,
    /// The union of its units' boxes.
    bounds: Aabb,
}

/// What the near pass tests as one box (`near_cull=on`).
#[derive(Clone)]
struct NearUnit {
    /// Its least view distance.
    distance: f32,
    /// Its instance.
    inst: u32,
    /// Its leaves: a range of the frame's near `(instance, leaf)` pairs.
    leaves: std::ops::Range<u32>,
    /// The instance's mesh has one leaf: drawn whole.
    whole: bool,
    /// Its triangle references (what a batch's size counts, though a batch draws only the
    /// triangles its leaves own: the borrowed ones come last, [`owned`]).
    count: u32,
    /// The triangles its leaves own ([`owned`]; a mesh's drawn whole: all): what its test
    /// saves when it is hidden.
    owned: u32,
    /// The union of its leaves' boxes.
    bounds: Aabb,
}

/// One draw per instance list of the pool.
fn make_draws<'s>(
    scene: &'s Scene,
    view: &View,
    lists: &[(InstanceRec, ItemId, std::ops::Range<usize>)],
    pool: &'s [u32],
) -> Vec<Draw<'s>> {
    lists
        .iter()
        .filter_map(|(rec, first_item, range)| {
            Some(Draw {
                mesh: scene.node(rec.node).mesh()?,
                triangles: DrawTriangles::List(&pool[range.clone()]),
                clip_from_object: view.clip_from_object(&rec.world_from_object),
                first_item: *first_item,
            })
        })
        .collect()
}

/// A frame's lists of the instances met and of their leaves, kept from frame to frame and
/// cleared before each: on a view of many leaves they hold megabytes, which fresh vectors
/// faulted in page by page every frame (as [`near::NearScratch`]).
#[derive(Default)]
struct FrameLists {
    instances: Vec<(InstanceRec, ItemId, Mat4)>,
    near: Vec<(u32, u32)>,
    far: Vec<(u32, u32)>,
    deferred: Vec<(u32, u32, f32, u32)>,
    /// `plane=cost`: the deferred leaves' distances and triangles.
    plane_leaves: Vec<(f32, u32)>,
}

impl FrameLists {
    fn clear(&mut self) {
        self.instances.clear();
        self.near.clear();
        self.far.clear();
        self.deferred.clear();
        self.plane_leaves.clear();
    }

    fn memory_bytes(&self) -> usize {
        self.instances.capacity() * std::mem::size_of::<(InstanceRec, ItemId, Mat4)>()
            + (self.near.capacity() + self.far.capacity()) * 8
            + self.deferred.capacity() * std::mem::size_of::<(u32, u32, f32, u32)>()
            + self.plane_leaves.capacity() * 8
    }
}

/// Groups `(key, leaf)` pairs sorted by key into ranges.
fn group_ranges<K: PartialEq + Copy>(pairs: &[(K, u32)]) -> Vec<(K, std::ops::Range<usize>)> {
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..=pairs.len() {
        if i == pairs.len() || pairs[i].0 != pairs[start].0 {
            if i > start {
                out.push((pairs[start].0, start..i));
            }
            start = i;
        }
    }
    out
}

impl Renderer for Lzb {
    fn name(&self) -> &'static str {
        "lzb"
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        self.render_frame(view, frame, None)
    }

    fn memory_bytes(&self) -> usize {
        self.memory_bytes_of_all()
    }

    /// The rasterizer's private frames, the pyramid of `near_cull` and `far_cull`, the direct
    /// frames' screening pyramid.
    fn prepare(&mut self, width: u32, height: u32) -> Result<()> {
        crate::prepare_raster(&mut self.raster, &self.scene, width, height);
        if self.opts.near_cull || self.opts.far_cull {
            crate::sized_pyramid(&mut self.pyramid, width, height)?;
        }
        if let Some(direct) = &mut self.direct {
            direct.prepare(&mut self.raster, width, height)?;
        }
        Ok(())
    }

    fn is_conservative(&self) -> bool {
        self.opts.mode == Mode::Lazy
    }
}

impl Lzb {
    /// A frame, alone (`share` `None`) or as one rank of §IV's parallel LZB ([`shared`]).
    fn render_frame(
        &mut self,
        view: &View,
        frame: &mut Frame,
        mut share: Option<&mut dyn shared::FrameShare>,
    ) -> Result<FrameStats> {
        crate::check_frame(view, frame)?;
        if let Some(direct) = &mut self.direct {
            if let Some(mut stats) = direct.render_if_due(&mut self.raster, view, frame)? {
                stats.counters.add("octree_leaf", self.leaf_size as u64);
                return crate::end_frame(&self.raster, stats);
            }
            direct.arm(&mut self.payoff, self.raster.thread_count());
        }
        let (start, cleared, mut stats) = crate::begin_frame(&mut self.raster, view, frame)?;
        stats.counters.add("octree_leaf", self.leaf_size as u64);
        let mut payoff = self.payoff.begin(cleared);
        let mut ctx = FrameCtx::new(view, self.cull_backfaces);

        // Step 2 (§II.B): the partition plane (with `plane=cost`, chosen after step 1).
        let choice = self.partition_plane(&ctx, &mut stats);
        let mut z_clip = match choice {
            PlaneChoice::At(z) => z,
            PlaneChoice::Cost(_) => ctx.near,
        };
        ctx.near_limit = z_clip * (1.0 + NEAR_MARGIN);

        // Step 1: frustum culling collecting leaves, split by the plane.
        let t = Instant::now();
        let mut lists = std::mem::take(&mut self.lists);
        lists.clear();
        let mut walk = Walk {
            walk: SceneWalk::new(&self.scene, &ctx.view),
            lzb: self,
            ctx: &ctx,
            instances: std::mem::take(&mut lists.instances),
            near: std::mem::take(&mut lists.near),
            far: std::mem::take(&mut lists.far),
            // §IV: every rank splits by rank 0's plane, known after the walk.
            deferred: (matches!(choice, PlaneChoice::Cost(_)) || share.is_some())
                .then(|| std::mem::take(&mut lists.deferred)),
        };
        walk.walk.stats = stats;
        walk.run();
        let Walk {
            walk,
            instances,
            mut near,
            mut far,
            deferred,
            ..
        } = walk;
        stats = walk.finish("lzb")?;
        if let Some(deferred) = deferred {
            if let PlaneChoice::Cost(hits) = &choice {
                let leaves = &mut lists.plane_leaves;
                leaves.extend(deferred.iter().map(|&(_, _, d, n)| (d, n)));
                let pixels = f64::from(view.width()) * f64::from(view.height());
                z_clip = cost_plane(
                    leaves,
                    hits,
                    pixels,
                    self.ns_per_triangle,
                    self.ns_per_ray,
                    self.near_share,
                    self.pvl_share,
                    self.ns_per_far_leaf,
                    ctx.near,
                    ctx.far,
                );
                self.remember_plane(*view.camera(), z_clip);
            }
            if let Some(share) = share.as_deref_mut() {
                z_clip = share.plane(z_clip)?;
            }
            ctx.near_limit = z_clip * (1.0 + NEAR_MARGIN);
            for &(inst, leaf, d, _) in &deferred {
                if d < ctx.near_limit {
                    near.push((inst, leaf));
                } else {
                    far.push((inst, leaf));
                }
            }
            lists.deferred = deferred;
        }
        stats
            .counters
            .add("z_clip_permille_of_far", (z_clip / ctx.far * 1000.0) as u64);
        stats.counters.add("near_leaves", near.len() as u64);
        stats.counters.add("far_leaves", far.len() as u64);
        let far_leaves = far.len();
        // The near and the far leaves' triangle references, what `plane=cost` weighs them by.
        let references = |leaves: &[(u32, u32)]| -> u64 {
            leaves
                .iter()
                .map(
                    |&(inst, leaf)| match &self.accel[instances[inst as usize].0.node.index()] {
                        Accel::Mesh { octree, .. } => u64::from(octree.nodes()[leaf as usize].count),
                        _ => 0,
                    },
                )
                .sum()
        };
        let (near_references, far_references) = (references(&near), references(&far));
        stats.phases.add(Phase::Cull, t.elapsed());

        // No leaf drawn yet (`owned`: the near pass, and the far leaves of a frame given up).
        self.drawn.reset(
            instances.len(),
            DRAWN_WORDS_PER_LEAF * (near.len() + far.len()) + DRAWN_MIN_WORDS,
        );
        // Step 3: local rendering of S_near with the z-buffer (occlusion-culled front to back
        // with `near_cull=on`).
        // §IV: by rank 0, whose near depth buffer every rank then receives.
        if share.as_deref().is_none_or(|s| s.rank() == 0) {
            if self.opts.near_cull {
                self.draw_near_culled(view, frame, &instances, &near, &mut stats, &mut payoff)?;
            } else {
                self.draw_leaves(view, frame, &instances, &near, &mut stats, "near_triangles");
            }
        }
        crate::check_cancel(&self.raster)?;
        if let Some(share) = share.as_deref_mut() {
            share.depth(frame)?;
        }
        // Step 3½ (`far_cull=on`): the far leaves hidden behind the near set dropped.
        // Without a near leaf nothing is drawn that could hide one: no test could pass.
        let mut far_cull_time = Duration::ZERO;
        if self.opts.far_cull && !far.is_empty() && !near.is_empty() && !payoff.given_up() {
            let t = Instant::now();
            let culled = self.cull_far(view, frame, &instances, &mut far, &mut stats)?;
            stats.counters.add("far_culled_leaves", culled);
            far_cull_time = t.elapsed();
        }

        // Step 4: the unfinished pixels: nothing drawn nearer than the plane.
        let t = Instant::now();
        let (w, h) = (view.width(), view.height());
        let d_clip = ctx.near / z_clip;
        let unfinished = |d: f32| d.is_nan() || d <= d_clip;
        stats.counters.add(
            "unfinished_pixels",
            frame.depth().iter().filter(|&&d| unfinished(d)).count() as u64,
        );
        // §III.C: object-oriented ray casting: only unfinished pixels inside the projection of
        // a far leaf, each once (the done-mask). Without far leaves no pixel is cast: the
        // masks and the tile walk below are skipped (a frame whose plane lies at the far
        // plane, every leaf near), nor in a frame given up in its near pass.
        let no_rays = (self.opts.oor && far.is_empty()) || payoff.given_up();
        let mut cast_mask: Vec<bool> = if no_rays {
            Vec::new()
        } else {
            frame.depth().iter().map(|&d| unfinished(d)).collect()
        };
        if self.opts.oor && !no_rays {
            let bands = (OOR_BANDS_PER_THREAD * self.raster.thread_count()) as u32;
            let accel = &self.accel;
            let marked = self.raster.install(|| {
                oor::mark(
                    &cast_mask,
                    &far,
                    &instances,
                    accel,
                    view.camera().eye,
                    [w, h],
                    ctx.near,
                    bands,
                )
            });
            let (polygons, instances_skipped) = (marked.polygons, marked.instances_skipped);
            let done = marked.mask;
            stats.counters.add("oor_polygons", polygons);
            stats.counters.add("oor_instances_skipped", instances_skipped);
            cast_mask = done;
        } else if no_rays {
            stats.counters.add("oor_polygons", 0);
            stats.counters.add("oor_instances_skipped", 0);
        }
        // In tiles of 8×8 pixels, row-major within a tile: neighbouring rays meet the same
        // nodes and triangles, which a chunk then finds in cache (and §III.D's neighbour is
        // still the previous ray).
        const TILE: u32 = 8;
        let mut pixels: Vec<u32> = Vec::new();
        for ty in (0..h).step_by(TILE as usize).filter(|_| !no_rays) {
            for tx in (0..w).step_by(TILE as usize) {
                for y in ty..(ty + TILE).min(h) {
                    for x in tx..(tx + TILE).min(w) {
                        let i = y * w + x;
                        if cast_mask[i as usize] {
                            pixels.push(i);
                        }
                    }
                }
            }
        }
        if let Some(share) = share.as_deref() {
            shared::keep_share(&mut pixels, CHUNK, share.rank(), share.size());
        }
        stats.phases.add(Phase::Other, t.elapsed());

        // Step 5: rays, in chunks over threads; PVLs merged without duplicates.
        let t = Instant::now();
        let naive = self.opts.mode == Mode::Naive;
        let this: &Lzb = self;
        // With payoff, in waves: before each, the frame is given up once its rays do not pay.
        // With a live frame control, in waves too: the cancellation is checked and the
        // progress (rays cast of the rays to cast) reported between two.
        let control = &this.raster.config().control;
        let wave = if self.direct.is_some() || control.is_live() {
            RAY_WAVE
        } else {
            pixels.len().max(1)
        };
        let mut results: Vec<Caster<'_>> = Vec::new();
        for (k, pixels_of_wave) in pixels.chunks(wave).enumerate() {
            crate::check_cancel(&this.raster)?;
            crate::report_part(&this.raster, (k * wave) as u64, pixels.len() as u64);
            if self.direct.is_some() && payoff.progressed((k * wave) as f64 / pixels.len() as f64) {
                break;
            }
            results.extend(this.raster.install(|| {
                pixels_of_wave
                    .par_chunks(CHUNK)
                    .map(|chunk| {
                        let mut caster = Caster::new(this, &ctx, naive);
                        if this.opts.packets {
                            // The pixels come in 8×8 tiles (step 4), so a run of 64 is one
                            // tile or a few rows of neighbours.
                            for packet in chunk.chunks(occult_spatial::PACKET) {
                                if naive {
                                    caster.cast_packet(packet, w);
                                } else {
                                    caster.cast_packet_hits(packet, w);
                                }
                            }
                        } else {
                            for &i in chunk {
                                if let Some((t, item)) = caster.cast(i % w, i / w) {
                                    caster.hits.push((i, t, item));
                                }
                            }
                        }
                        caster
                    })
                    .collect::<Vec<_>>()
            }));
        }
        crate::check_cancel(&self.raster)?;
        let mut pairs: Vec<(ItemId, u32)> = Vec::new();
        let mut recs = std::collections::HashMap::<ItemId, InstanceRec, crate::hash::FxBuild>::default();
        let mut hits = Vec::new();
        let (mut rays, mut tests, mut coherent, mut leaves, mut resolved, mut ray_nodes) = (0, 0, 0, 0, 0, 0);
        for c in results {
            rays += c.rays;
            tests += c.tri_tests;
            coherent += c.coherent_starts;
            resolved += c.resolved;
            stats.nodes_visited += c.counters.nodes_visited;
            ray_nodes += c.counters.nodes_visited;
            leaves += c.counters.leaves_visited;
            pairs.extend(c.pvl.iter().copied());
            pairs.extend(&c.pvl_hits);
            recs.extend(c.instances.iter().map(|(k, v)| (*k, *v)));
            hits.extend(c.hits);
        }
        // §IV: the ranks' PVLs, united at rank 0, which alone draws.
        if let Some(share) = share {
            if !shared::unite_pvl(share, &mut pairs, &mut recs)? {
                stats.total = start.elapsed();
                self.lists = FrameLists {
                    instances,
                    near,
                    far,
                    ..lists
                };
                return crate::end_frame(&self.raster, stats);
            }
        }
        // The chunks' sets overlap: one entry per (instance, leaf). A `pvl=hits` list (hundreds
        // of thousands of triangles) is left in the runs its packets made, each of one
        // instance, sorted and without duplicates: the stamps below drop most of what two
        // runs of an instance share (a triangle drawn twice draws the same frame).
        if self.opts.pvl != Pvl::Hits {
            pairs.sort_unstable();
            pairs.dedup();
        }
        stats.rays_cast += rays;
        stats.counters.add_all([
            ("rays", rays),
            ("ray_tri_tests", tests),
            ("ray_leaves_visited", leaves),
            ("ray_nodes_visited", ray_nodes),
            ("coherent_starts", coherent),
            ("rays_resolved", resolved),
        ]);
        let fine_rays_time = t.elapsed();
        stats.phases.add(Phase::Rays, fine_rays_time);

        if payoff.given_up() {
            // Given up (`crate::payoff`): its far leaves drawn directly, whatever rays were
            // cast (the near set is drawn whole, `far_cull`'s hidden leaves dropped).
            self.draw_leaves(view, frame, &instances, &far, &mut stats, "far_direct_triangles");
        } else if naive {
            // §II: the first hits are shaded directly (depth near / view distance).
            for (i, t, item) in hits {
                frame.write_fragment(i % w, i / w, ctx.near / t, item);
            }
        } else {
            // §III.A: the PVL, drawn by the z-buffer.
            let t = Instant::now();
            let groups: Vec<_> = group_ranges(&pairs)
                .into_iter()
                .map(|(key, r)| (recs[&key], key, r))
                .collect();
            let pvl_leaves: Vec<u32> = pairs.iter().map(|&(_, l)| l).collect();
            let entries = match (self.opts.pvl, self.opts.caster) {
                (Pvl::Triangles | Pvl::Hits, _) => Entries::Triangles,
                (Pvl::Leaves, CasterKind::Bvh) => Entries::BvhLeaves,
                (Pvl::Leaves, CasterKind::Octree) => Entries::OctreeLeaves,
            };
            let counter = if entries == Entries::Triangles {
                "pvl_entries_triangles"
            } else {
                "pvl_leaves"
            };
            stats.counters.add(counter, pvl_leaves.len() as u64);
            let mut pool = Vec::new();
            // One stamp per instance however many runs it has (`pvl=hits`).
            let stamps = (self.opts.pvl == Pvl::Hits).then(|| {
                let mut of_base = std::collections::HashMap::<ItemId, u32, crate::hash::FxBuild>::default();
                for (_, key, _) in &groups {
                    let next = of_base.len() as u32;
                    of_base.entry(*key).or_insert(next);
                }
                let first = self.reserve_stamps(of_base.len() as u32);
                groups
                    .iter()
                    .map(|(_, key, _)| first + of_base[key])
                    .collect::<Vec<u32>>()
            });
            let lists = self.emit(&groups, &pvl_leaves, &mut pool, entries, stamps.as_deref());
            stats.counters.add("pvl_triangles", pool.len() as u64);
            stats.phases.add(Phase::Other, t.elapsed());
            let draws = make_draws(&self.scene, view, &lists, &pool);
            crate::rasterize(&mut self.raster, view, frame, &draws, &mut stats);
        }
        // A cancelled frame measures nothing: the rates below stay as they were.
        crate::check_cancel(&self.raster)?;
        // A frame given up is finished whole too: what it shows leads the next.
        if self.opts.near_cull && self.opts.near_temporal {
            let t = Instant::now();
            self.remember_visible(frame, &instances);
            stats.phases.add(Phase::Other, t.elapsed());
        }
        // The rays paid when the time outside rasterization is no more than what the
        // triangles they removed from a direct frame's work would have cost at this frame's
        // rate (with the payoff's least allowance). The in-frame balance is not fed with the
        // near pass's rate: a few large near triangles make a triangle look costly, which
        // would put off giving up the first frame.
        let total = start.elapsed();
        let raster = stats.phases.get(Phase::Raster);
        let removed = payoff.work().saturating_sub(stats.triangles_submitted);
        let gain = raster.as_secs_f64() * removed as f64 / stats.triangles_submitted.max(1) as f64;
        let rays_paid = (total.saturating_sub(raster)).as_secs_f64() <= gain + MIN_ALLOWANCE_TIME.as_secs_f64();
        if !payoff.given_up() {
            // The rates `plane=cost` weighs (halfway to each new measurement).
            let blend = |old: f64, new: f64| {
                if new.is_finite() && new > 0.0 {
                    0.5 * (old + new)
                } else {
                    old
                }
            };
            // Only from frames that drew enough triangles for their rate to be one: a few
            // large triangles over the screen (a view down the street to the sky) would make a
            // triangle look as dear as its fill, and the next frame cast rays instead.
            let submitted = stats.triangles_submitted;
            if submitted >= MIN_RATE_TRIANGLES {
                self.ns_per_triangle = blend(self.ns_per_triangle, raster.as_nanos() as f64 / submitted as f64);
            }
            // The near pass's share, from a near set large enough to say (`near_cull=on`): the
            // triangles it drew per triangle reference of the near leaves.
            let drawn = stats.counters.get("near_triangles");
            if self.opts.near_cull && near_references >= MIN_RATE_TRIANGLES {
                self.near_share = 0.5 * (self.near_share + drawn as f64 / near_references as f64);
            }
            let pvl = stats.counters.get("pvl_triangles");
            if far_references > 0 && !naive {
                // An empty PVL is a measurement too (a share of 0), unlike a zero time.
                self.pvl_share = 0.5 * (self.pvl_share + pvl as f64 / far_references as f64);
                // With `far_cull`, its tests are part of what a far leaf costs.
                let other = (stats.phases.get(Phase::Other) + far_cull_time).as_nanos() as f64;
                self.ns_per_far_leaf = blend(self.ns_per_far_leaf, other / far_leaves as f64);
            }
            // The fine rays alone: the coarse ones are thin first-hit rays, several times
            // cheaper, and a frame that cast none but them made rays look cheap to the next.
            if stats.rays_cast > 0 {
                let ns = fine_rays_time.as_nanos() as f64 / stats.rays_cast as f64;
                self.ns_per_ray = blend(self.ns_per_ray, ns);
            }
        }
        self.payoff.end(&payoff);
        if let Some(direct) = &mut self.direct {
            stats.counters.add_all(payoff.counters());
            let t = Instant::now();
            direct.culled(
                view,
                frame,
                start.elapsed(),
                &mut stats,
                rays_paid && !payoff.given_up(),
            )?;
            stats.phases.add(Phase::Other, t.elapsed());
        }
        stats.total = start.elapsed();
        self.lists = FrameLists {
            instances,
            near,
            far,
            ..lists
        };
        crate::end_frame(&self.raster, stats)
    }

    fn memory_bytes_of_all(&self) -> usize {
        self.accel.iter().map(Accel::memory_bytes).sum::<usize>()
            + self.stamps.iter().map(|s| s.capacity() * 4).sum::<usize>()
            + self.drawn.memory_bytes()
            + self.raster.memory_bytes()
            + self.pyramid.as_ref().map_or(0, ZPyramid::memory_bytes)
            + self.near_visible.capacity() * std::mem::size_of::<(ItemId, u32)>()
            + self.near_scratch.memory_bytes()
            + self.lists.memory_bytes()
    }
}

#[cfg(test)]
impl crate::direct::tests::ForceDirect for Lzb {
    fn force(&mut self, n: u32, abandon: bool) {
        let direct = self.direct.as_mut().expect("payoff is on by default");
        direct.force(n, abandon);
        self.payoff.force_stop = abandon;
    }

    fn direct(&self) -> &DirectFrames {
        self.direct.as_ref().expect("payoff is on by default")
    }
}

#[cfg(test)]
mod tests;
