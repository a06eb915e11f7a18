//! Occlusion culling of mesh clusters through a max z-pyramid, in two passes.
//!
//! See docs/clusters.md for the measurements and what limits it.
//!
//! # References
//! - N. Greene, M. Kass, G. Miller, *Hierarchical Z-Buffer Visibility* (SIGGRAPH 1993): the
//!   box test through a max z-pyramid (`hzb::boxtest`: the whole box for clusters, Georges'
//!   faces for instances).
//! - C. Georges, *Obscuration Culling on Parallel Graphics Architectures* (1995), §3.3: last
//!   frame's visible set drawn first, untested, as the occluders of the frame.
//! - A. Kapoulkine, meshoptimizer's clusterizer (`meshopt_buildMeshletsSpatial`), through the
//!   `meshopt` crate: the clusters.
//!
//! # What it does
//! `hzb`'s units are the nodes of an octree over each mesh: on views where visible triangles
//! are spread over every leaf (a city seen from above, foliage), no leaf is hidden, and its
//! walk tests and draws in many small batches. This renderer culls **clusters**: every mesh
//! of more than `size` triangles is split once, at preparation, into spatially compact
//! clusters of at most `size` triangles with tight boxes (meshoptimizer's spatial
//! clusterizer, which minimizes the clusters' surface area); smaller meshes are one cluster.
//! The scene's mesh instances are flattened once (each with its world box and the offset of
//! its clusters in a bit set of the scene's cluster instances). A frame
//!
//! 1. **draws last frame's visible clusters** of the instances in view, untested, in one
//!    call over the rasterizer's threads (`temporal`; only while at least `trust` of last
//!    frame's set in view stayed visible: after a jump of the view it is hidden geometry, not
//!    occluders; and only while it made frames faster, `weigh`, [`crate::list_choice`]), and
//!    builds the pyramid over them;
//! 2. takes the instances in view **front to back** (nearest box point first) in windows of
//!    at least `batch` triangles (or a quarter of what the first pass drew, if more), each
//!    next window twice as large, up to [`MAX_BATCH`]. The instances of a window are tested in
//!    parallel against the pyramid as it stands: an instance whose box is hidden (Georges'
//!    face test) is skipped whole; otherwise each of its clusters is tested (the frustum,
//!    unless the instance is wholly inside it, then Greene's whole-box test, one pyramid test
//!    a cluster), down a tree of groups of [`GROUP`] clusters in Morton order: a group
//!    hidden hides the clusters below it in one test (while a mesh's groups are found hidden
//!    often enough to pay, `GroupRate`). The clusters not hidden that the first pass did not
//!    draw are drawn as one batch, and the pyramid is updated over the batch's screen
//!    region: the first windows hold the near occluders, the later ones are large enough for
//!    the rasterizer's threads.
//!    With `behind` (the default), a cluster not hidden whose box lies behind its instance's
//!    centre (its nearest point farther from the eye than the centre of the instance's box)
//!    waits: its pyramid query (rectangle and nearest depth) is asked again once the
//!    window's batch is drawn, beside the next window's tests, and it is drawn in the next
//!    batch if still not hidden. The front of a building hides its back, which a window's
//!    tests, made before any of it is drawn, cannot see;
//! 3. keeps as visible for the next frame the clusters the second pass found not hidden
//!    (those the first pass drew included: they are tested too, and drop out once hidden).
//!
//! An instance all of whose clusters are drawn in one batch is drawn whole; otherwise its clusters are one
//! cluster draw ([`DrawTriangles::Clusters`]: each cluster's vertices projected once).
//!
//! **Exact.** A cluster is skipped only when its box is hidden behind depth already drawn
//! this frame, and depth only grows while a frame is drawn: the frame is `zbuffer`'s,
//! bit for bit (item ids are the meshes' own triangle indices; the clusters only list them).
//!
//! Cost: O(instances in view + clusters of the instances not hidden) tests per frame (fewer
//! where groups of clusters are hidden whole), and
//! about `log2(MAX_BATCH / batch)` batches beyond the first pass, one more per [`MAX_BATCH`]
//! triangles in view after that (and one for the last window's waiting clusters); a
//! waiting cluster's second query reads only the pyramid. The flattened instances
//! are bounded ([`MAX_INSTANCES`], checked before anything is allocated): scenes of more mesh
//! instances are for `hzb`, whose walk never flattens the scene.
//!
//! # Counters
//! `clusters_tested`, `clusters_culled` (hidden or outside the frustum), `instances_culled`
//! (boxes hidden whole), `first_triangles` (triangles the first pass drew), `batches` (draws of
//! the second pass), `removed_triangles` (triangles of the instances in view not drawn),
//! `precision_pct` (the share of last frame's visible clusters in view still visible, that
//! `trust` weighs), `clusters_deferred` (clusters that waited for their window's front,
//! `behind`), `group_tests` (tests of groups of clusters), and the payoff's `payoff_direct`
//! and `payoff_screened` ([`crate::direct`]).

use std::sync::Arc;
use std::time::Instant;

use occult_core::{Aabb, Affine3A, Containment, Mat4, Mesh, NodeId, NodeKind, Scene, Vec3, View};
use occult_raster::{
    Draw, DrawTriangles, Frame, Meshlets, PixelRect, PyramidCounts, Rasterizer, ZPyramid, MAX_CLUSTER_VERTICES,
};

use crate::direct::DirectFrames;
use crate::hzb::boxtest::{screen_rect, Occlusion};
use crate::list_choice::ListChoice;
use rayon::prelude::*;

use crate::nodes::per_node;
use crate::{AlgorithmInfo, FrameStats, ParamDoc, Phase, RenderError, RenderOptions, Renderer, Result};

/// Most mesh instances a scene may have to be flattened (about 100 bytes each).
pub const MAX_INSTANCES: u64 = 1 << 22;
/// Largest batch of the second pass, triangles: large enough for the rasterizer's threads.
pub const MAX_BATCH: u64 = 1 << 19;
/// Default [`ClusterOptions::trust`].
pub const TRUST: f64 = 0.4;
/// Largest cluster meshoptimizer builds, triangles.
pub const MAX_CLUSTER: usize = 512;

/// Tunables of [`ClusterCulling`].
#[derive(Clone, Debug, PartialEq)]
pub struct ClusterOptions {
    /// Most triangles of a cluster: a multiple of 4 in `8..=512`.
    pub size: usize,
    /// Triangles of the second pass's first batch (≥ 1); each next batch holds twice as many,
    /// up to [`MAX_BATCH`].
    pub batch: u64,
    /// Draw last frame's visible clusters first, untested (§3.3 of Georges).
    pub temporal: bool,
    /// Least share (0..=1) of last frame's visible clusters in view that stayed visible for
    /// the first pass to be drawn: below, the view moved too far for last frame's set to be
    /// this frame's occluders, and the second pass draws the frame alone.
    pub trust: f64,
    /// Draw the first pass only while frames that drew it were faster than frames that did
    /// not ([`crate::list_choice`]).
    pub weigh: bool,
    /// Draw runs of frames directly, as `frustum` does, while culled frames are slower than
    /// such direct frames ([`crate::direct`]).
    pub payoff: bool,
    /// Draw the clusters found not hidden behind their instance's centre after the front of
    /// their window, tested again: the front of a building hides its back.
    pub behind: bool,
    /// Test each mesh's clusters down its tree of groups ([`MeshClusters::groups`]) while
    /// that pays; off: every cluster by its own test.
    pub groups: bool,
}

impl Default for ClusterOptions {
    fn default() -> Self {
        Self {
            size: 64,
            batch: 1 << 14,
            temporal: true,
            trust: TRUST,
            weigh: true,
            payoff: true,
            behind: true,
            groups: true,
        }
    }
}

impl ClusterOptions {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] naming the setting.
    pub fn validate(&self) -> Result<()> {
        if !(8..=MAX_CLUSTER).contains(&self.size) || !self.size.is_multiple_of(4) {
            return Err(RenderError::BadParameter(format!(
                "clusters: size must be a multiple of 4 from 8 to {MAX_CLUSTER}, not {}",
                self.size
            )));
        }
        if self.batch == 0 {
            return Err(RenderError::BadParameter("clusters: batch must be at least 1".into()));
        }
        if !(0.0..=1.0).contains(&self.trust) {
            return Err(RenderError::BadParameter(format!(
                "clusters: trust must be from 0 to 1, not {}",
                self.trust
            )));
        }
        Ok(())
    }
}

/// Registry entry of [`ClusterCulling`].
pub static INFO: AlgorithmInfo = AlgorithmInfo {
    name: "clusters",
    summary: "occlusion culling of mesh clusters (meshoptimizer) through a max z-pyramid: last frame's visible clusters first, then the rest front to back in growing batches",
    params: &[
        ParamDoc {
            key: "size",
            default: "64",
            help: "most triangles per cluster, a multiple of 4 from 8 to 512",
        },
        ParamDoc {
            key: "batch",
            default: "16384",
            help: "triangles of the first front-to-back batch (>= 1); each next one doubles, up to 524288",
        },
        ParamDoc {
            key: "temporal",
            default: "on",
            help: "draw last frame's visible clusters first, untested",
        },
        ParamDoc {
            key: "trust",
            default: "0.4",
            help: "draw the first pass only while at least this share (0..=1) of last frame's visible clusters in view stayed visible; 0 = always",
        },
        ParamDoc {
            key: "weigh",
            default: "on",
            help: "draw the first pass only while frames that drew it were faster than frames that did not (the last of each; the other way measured again after 16, 32, 64 frames); off = by trust alone",
        },
        ParamDoc {
            key: "payoff",
            default: "on",
            help: "draw runs of frames as frustum does while culled frames are slower than such direct frames",
        },
        ParamDoc {
            key: "behind",
            default: "on",
            help: "clusters not hidden that lie behind their instance's centre wait for the front of their window to be drawn and are tested again; off = drawn with it",
        },
        ParamDoc {
            key: "groups",
            default: "on",
            help: "test each mesh's clusters down a tree of groups of 8 (a hidden group hides its clusters in one test) while that pays; off = every cluster by its own test",
        },
    ],
    counters: &[
        "clusters_tested",
        "clusters_culled",
        "instances_culled",
        "first_triangles",
        "batches",
        "removed_triangles",
        "precision_pct",
        "clusters_deferred",
        "group_tests",
        crate::direct::COUNTER,
        crate::direct::SCREENED,
    ],
    conservative: true,
    bands: true,
    build: |scene, options, params| {
        let mut co = ClusterOptions::default();
        crate::params::read_params!(params, co, {
            size: "size",
            batch: "batch",
            temporal: flag "temporal",
            trust: "trust",
            weigh: flag "weigh",
            payoff: flag "payoff",
            behind: flag "behind",
            groups: flag "groups",
        });
        Ok(Box::new(ClusterCulling::new(scene, options, &co)?))
    },
};

/// The clusters of one mesh, as the rasterizer draws them ([`Meshlets`]: each cluster's
/// distinct vertices, transformed once a draw), and each cluster's box.
#[derive(Clone, Debug, Default)]
pub(crate) struct MeshClusters {
    meshlets: Meshlets,
    /// Object-space bounds of each cluster.
    boxes: Vec<Aabb>,
    /// Their union.
    bounds: Aabb,
    /// The clusters in Morton order of their boxes' centres.
    order: Vec<u32>,
    /// Boxes of groups of [`GROUP`] over that order: `groups[0][i]` bounds the clusters
    /// `order[GROUP * i..][..GROUP]`, `groups[k][i]` the groups `groups[k - 1][GROUP * i..][..GROUP]`,
    /// up to a level of at most [`GROUP`] boxes; none for a mesh of at most [`GROUP`] clusters.
    /// A group hidden hides every cluster below it, in one test.
    groups: Vec<Vec<Aabb>>,
}

/// How often a mesh's groups of clusters were found hidden (the count of each instance
/// tested added to three quarters of the counts before).
///
/// A group's test costs about a cluster's; found hidden, it saves the tests of the
/// [`GROUP`] or more clusters below it, found not hidden it adds one. Groups are tested while
/// more than one test in [`GROUP`] finds its group hidden (and until the rate is known); where
/// fewer do (foliage, whose groups overlap; a mesh mostly in view) the clusters are tested
/// directly, and once the mesh was met [`GROUP_RETRY`] times so, its groups are tested again
/// (in every instance of it in the next window: a window's instances are tested together).
#[derive(Clone, Copy, Debug, Default)]
struct GroupRate {
    tests: f32,
    hidden: f32,
    /// Times the mesh was met since its groups were last tested.
    skipped: u32,
}

/// See [`GroupRate`].
const GROUP_RETRY: u32 = 16;

impl GroupRate {
    /// Whether to test the mesh's groups this time.
    fn pays(&self) -> bool {
        self.tests < GROUP as f32 || self.hidden * GROUP as f32 > self.tests || self.skipped >= GROUP_RETRY
    }

    /// Records a test of an instance: `tests` group tests of which `hidden` found the group
    /// hidden (none: groups were not tested).
    fn record(&mut self, tests: u64, hidden: u64) {
        if tests == 0 {
            self.skipped += 1;
            return;
        }
        self.skipped = 0;
        self.tests = self.tests * 0.75 + tests as f32;
        self.hidden = self.hidden * 0.75 + hidden as f32;
    }
}

/// Children of a group of clusters ([`MeshClusters::groups`]).
pub const GROUP: usize = 8;

/// The Morton order of `boxes`' centres within `bounds`, and the boxes of groups of
/// [`GROUP`] over it, level by level ([`MeshClusters::groups`]).
fn cluster_groups(boxes: &[Aabb], bounds: Aabb) -> (Vec<u32>, Vec<Vec<Aabb>>) {
    let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
    if boxes.len() <= GROUP {
        return (order, Vec::new());
    }
    let scale = Vec3::splat(1023.0) / bounds.size().max(Vec3::splat(f32::MIN_POSITIVE));
    let key = |b: &Aabb| {
        let q = ((b.center() - bounds.min) * scale).clamp(Vec3::ZERO, Vec3::splat(1023.0));
        spread(q.x as u32) | spread(q.y as u32) << 1 | spread(q.z as u32) << 2
    };
    order.sort_by_key(|&c| (key(&boxes[c as usize]), c));
    let mut levels = Vec::new();
    let mut below: Vec<Aabb> = order.iter().map(|&c| boxes[c as usize]).collect();
    while below.len() > GROUP {
        let up: Vec<Aabb> = below
            .chunks(GROUP)
            .map(|g| g.iter().fold(Aabb::EMPTY, |u, b| u.union(*b)))
            .collect();
        levels.push(up.clone());
        below = up;
    }
    (order, levels)
}

/// The low 10 bits of `v` spread to every third bit (a Morton code's axis).
fn spread(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | x << 16) & 0x0300_00ff;
    x = (x | x << 8) & 0x0300_f00f;
    x = (x | x << 4) & 0x030c_30c3;
    (x | x << 2) & 0x0924_9249
}

impl MeshClusters {
    /// Splits `mesh` into clusters of at most `size` triangles (one when it has no more).
    ///
    /// # Errors
    /// [`RenderError::Raster`] when a cluster would break [`Meshlets::new`]'s rules (none
    /// does by construction: meshoptimizer's clusters have at most 255 vertices, the others
    /// are split before they reach 256).
    pub(crate) fn build(mesh: &Mesh, size: usize) -> Result<Self> {
        let n = mesh.triangle_count();
        let mut triangles: Vec<u32> = Vec::with_capacity(n);
        let mut starts = vec![0u32];
        if n > size {
            let indices: Vec<u32> = mesh.triangles().iter().flatten().copied().collect();
            let positions = meshopt::typed_to_bytes(mesh.positions());
            let adapter = meshopt::VertexDataAdapter::new(positions, std::mem::size_of::<Vec3>(), 0)
                .expect("Vec3 positions are 12-byte vertices");
            let min = (size / 2).next_multiple_of(4).min(size);
            let meshlets = meshopt::build_meshlets_spatial(&indices, &adapter, 255.min(3 * size), min, size, 0.5);
            // Each meshlet triangle names its corners; find the mesh triangle with those corners
            // (sorted, so that a rotation of the corners matches), each used once.
            let mut by_corners: Vec<([u32; 3], u32)> = mesh
                .triangles()
                .iter()
                .enumerate()
                .map(|(t, c)| (sorted(*c), t as u32))
                .collect();
            by_corners.sort_unstable();
            let mut used = vec![false; n];
            for m in meshlets.iter() {
                for t in m.triangles.chunks_exact(3) {
                    let key = sorted([0, 1, 2].map(|k| m.vertices[t[k] as usize]));
                    let mut i = by_corners.partition_point(|e| e.0 < key);
                    while i < by_corners.len() && by_corners[i].0 == key && used[by_corners[i].1 as usize] {
                        i += 1;
                    }
                    if i < by_corners.len() && by_corners[i].0 == key {
                        used[by_corners[i].1 as usize] = true;
                        triangles.push(by_corners[i].1);
                    }
                }
                if triangles.len() as u32 > *starts.last().expect("starts with 0") {
                    starts.push(triangles.len() as u32);
                }
            }
            // Triangles the clusterizer left out (degenerate ones), in clusters of their own
            // (of at most 64 triangles: at most 192 vertices, within a cluster's 256).
            let rest: Vec<u32> = (0..n as u32).filter(|&t| !used[t as usize]).collect();
            for chunk in rest.chunks(size.min(64)) {
                triangles.extend_from_slice(chunk);
                starts.push(triangles.len() as u32);
            }
        } else if n > 0 {
            // One cluster, split where it would hold more vertices than a cluster may.
            let mut distinct = std::collections::HashSet::new();
            for t in 0..n as u32 {
                let corners = mesh.triangles()[t as usize];
                let new = corners.iter().filter(|v| !distinct.contains(*v)).count();
                if distinct.len() + new > MAX_CLUSTER_VERTICES {
                    starts.push(t);
                    distinct.clear();
                }
                distinct.extend(corners);
                triangles.push(t);
            }
            starts.push(n as u32);
        }
        // Each cluster's triangles in ascending order, and the clusters by their first
        // triangle: a list of neighbouring clusters then reads the mesh's triangles and
        // vertices mostly forward, as a whole-mesh draw does, not scattered over the mesh.
        let mut spans: Vec<Vec<u32>> = starts
            .windows(2)
            .map(|w| {
                let mut c = triangles[w[0] as usize..w[1] as usize].to_vec();
                c.sort_unstable();
                c
            })
            .collect();
        spans.sort_unstable_by_key(|c| c[0]);
        triangles.clear();
        starts.truncate(1);
        for c in spans {
            triangles.extend_from_slice(&c);
            starts.push(triangles.len() as u32);
        }
        let boxes: Vec<Aabb> = starts
            .windows(2)
            .map(|w| {
                let tris = &triangles[w[0] as usize..w[1] as usize];
                Aabb::from_points(tris.iter().flat_map(|&t| mesh.triangle_positions(t as usize)))
            })
            .collect();
        let bounds = boxes.iter().fold(Aabb::EMPTY, |u: Aabb, b| u.union(*b));
        let (order, groups) = cluster_groups(&boxes, bounds);
        Ok(Self {
            meshlets: Meshlets::new(mesh, &triangles, &starts)?,
            boxes,
            bounds,
            order,
            groups,
        })
    }

    /// Number of clusters.
    pub(crate) fn len(&self) -> usize {
        self.boxes.len()
    }

    fn memory_bytes(&self) -> usize {
        self.meshlets.memory_bytes()
            + (self.boxes.capacity() + self.groups.iter().map(Vec::capacity).sum::<usize>())
                * std::mem::size_of::<Aabb>()
            + self.order.capacity() * 4
    }
}

fn sorted(mut c: [u32; 3]) -> [u32; 3] {
    c.sort_unstable();
    c
}

/// One mesh instance of the flattened scene.
#[derive(Clone, Debug)]
struct Placed {
    node: NodeId,
    world_from_object: Affine3A,
    first_item: u64,
    /// World-space bounds.
    bounds: Aabb,
    /// Offset of its clusters in the visible bit set.
    base: u64,
}

/// The cluster-culling renderer ([module doc](self)).
pub struct ClusterCulling {
    scene: Arc<Scene>,
    raster: Rasterizer,
    options: ClusterOptions,
    /// Per node: its clusters (meshes only).
    clusters: Vec<Option<MeshClusters>>,
    placed: Vec<Placed>,
    /// Per cluster instance: visible at the end of the last frame.
    visible: Vec<u64>,
    pyramid: Option<ZPyramid>,
    /// Frames drawn directly where culling does not pay (`payoff`).
    direct: Option<DirectFrames>,
    /// The share of last frame's visible clusters in view that this frame found visible too.
    precision: f64,
    /// Whether the last culled frame drew the first pass.
    last_first: bool,
    /// Frame times with the first pass and without it (`weigh`).
    choice: ListChoice,
    /// Per node: how often its mesh's groups of clusters were found hidden.
    group_rates: Vec<GroupRate>,
}

impl ClusterCulling {
    /// Clusters every mesh of `scene` and flattens its mesh instances.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for bad options or a scene of more than
    /// [`MAX_INSTANCES`] mesh instances; raster configuration errors.
    pub fn new(scene: Arc<Scene>, options: &RenderOptions, co: &ClusterOptions) -> Result<Self> {
        co.validate()?;
        let instances = mesh_instance_count(&scene);
        if instances > MAX_INSTANCES {
            return Err(RenderError::BadParameter(format!(
                "clusters: the scene has {instances} mesh instances, more than the {MAX_INSTANCES} this renderer flattens; use hzb, whose walk does not flatten the scene"
            )));
        }
        let raster = crate::scene_rasterizer(&scene, options)?;
        let clusters: Vec<Option<MeshClusters>> =
            per_node::<_, Result<Vec<_>>>(&raster, &scene, |node| match node.kind() {
                NodeKind::Mesh(m) => MeshClusters::build(m, co.size).map(Some),
                NodeKind::Group(_) => Ok(None),
            })?;
        let mut placed = Vec::with_capacity(instances as usize);
        let mut base = 0u64;
        scene.for_each_mesh_instance(|world_from_object, node, mesh, first_item| {
            let c = clusters[node.index()].as_ref().map_or(0, MeshClusters::len) as u64;
            if c > 0 {
                placed.push(Placed {
                    node,
                    world_from_object: *world_from_object,
                    first_item,
                    bounds: mesh.bounds().transformed(world_from_object),
                    base,
                });
                base += c;
            }
        });
        let direct = match co.payoff {
            true => Some(DirectFrames::new(Arc::clone(&scene), &raster)?),
            false => None,
        };
        let group_rates = vec![GroupRate::default(); scene.nodes().len()];
        Ok(Self {
            scene,
            raster,
            direct,
            precision: 1.0,
            last_first: true,
            choice: ListChoice::default(),
            group_rates,
            options: co.clone(),
            clusters,
            placed,
            visible: vec![0; base.div_ceil(64) as usize],
            pyramid: None,
        })
    }
}

/// Mesh instances the root reaches (saturating), without walking them: children have smaller
/// ids than their parents.
fn mesh_instance_count(scene: &Scene) -> u64 {
    let mut times = vec![0u64; scene.nodes().len()];
    times[scene.root().index()] = 1;
    let mut meshes = 0u64;
    for i in (0..=scene.root().index()).rev() {
        let t = times[i];
        if t == 0 {
            continue;
        }
        let node = &scene.nodes()[i];
        if node.mesh().is_some() {
            meshes = meshes.saturating_add(t);
        }
        for instance in node.instances() {
            let c = &mut times[instance.child.index()];
            *c = c.saturating_add(t);
        }
    }
    meshes
}

#[inline]
fn bit(bits: &[u64], i: u64) -> bool {
    bits[(i >> 6) as usize] >> (i & 63) & 1 != 0
}

#[inline]
fn set_bit(bits: &mut [u64], i: u64, on: bool) {
    let w = &mut bits[(i >> 6) as usize];
    if on {
        *w |= 1 << (i & 63);
    } else {
        *w &= !(1 << (i & 63));
    }
}

/// One instance's part of a batch: the clusters `scratch[start..end]`, or the whole mesh.
struct Pending<'a> {
    mesh: &'a Mesh,
    meshlets: &'a Meshlets,
    clip_from_object: Mat4,
    first_item: u64,
    /// `None`: the whole mesh.
    list: Option<(usize, usize)>,
}

/// Queues the clusters of one instance where `take(c)`: the whole mesh when that is all of
/// them, else the list of those clusters (gathered into `scratch`), one draw per instance.
/// Returns the triangles queued.
fn gather<'a>(
    pending: &mut Vec<Pending<'a>>,
    scratch: &mut Vec<u32>,
    mesh: &'a Mesh,
    mc: &'a MeshClusters,
    clip_from_object: Mat4,
    first_item: u64,
    take: impl Fn(usize) -> bool,
) -> u64 {
    let start = scratch.len();
    let mut triangles = 0;
    for c in 0..mc.len() {
        if take(c) {
            scratch.push(c as u32);
            triangles += mc.meshlets.triangle_count(c);
        }
    }
    let list = if scratch.len() - start == mc.len() {
        scratch.truncate(start);
        None
    } else if scratch.len() > start {
        Some((start, scratch.len()))
    } else {
        return 0;
    };
    pending.push(Pending {
        mesh,
        meshlets: &mc.meshlets,
        clip_from_object,
        first_item,
        list,
    });
    list.map_or(mesh.triangle_count(), |_| triangles) as u64
}

/// Rasterizes the queued parts, then empties the queue.
fn draw_pending(
    raster: &mut Rasterizer,
    view: &View,
    frame: &mut Frame,
    pending: &mut Vec<Pending<'_>>,
    scratch: &mut Vec<u32>,
    stats: &mut FrameStats,
) {
    let draws: Vec<Draw<'_>> = pending
        .iter()
        .map(|p| Draw {
            mesh: p.mesh,
            triangles: match p.list {
                None => DrawTriangles::All,
                Some((a, b)) => DrawTriangles::Clusters {
                    meshlets: p.meshlets,
                    list: &scratch[a..b],
                },
            },
            clip_from_object: p.clip_from_object,
            first_item: p.first_item,
        })
        .collect();
    if !draws.is_empty() {
        crate::rasterize(raster, view, frame, &draws, stats);
    }
    drop(draws);
    pending.clear();
    scratch.clear();
}

fn union_rect(a: Option<PixelRect>, b: PixelRect) -> PixelRect {
    match a {
        None => b,
        Some(d) => PixelRect {
            x0: d.x0.min(b.x0),
            y0: d.y0.min(b.y0),
            x1: d.x1.max(b.x1),
            y1: d.y1.max(b.y1),
        },
    }
}

/// Counts of one frame's second pass.
#[derive(Default)]
struct PassCounts {
    tested: u64,
    culled: u64,
    instances_culled: u64,
    batches: u64,
    /// Clusters of the instances in view visible last frame, and those of them visible now.
    was_visible: u64,
    still_visible: u64,
    /// Clusters behind their instance's centre, asked again after their window's front.
    deferred: u64,
    /// Groups of clusters tested.
    groups: u64,
}

impl PassCounts {
    /// Records that cluster `at` (its bit in `visible`) was found `shown` or hidden, as next
    /// frame's visible set and in the counts.
    fn record(&mut self, visible: &mut [u64], at: u64, shown: bool) {
        let was = bit(visible, at);
        self.was_visible += u64::from(was);
        self.still_visible += u64::from(was && shown);
        self.culled += u64::from(!shown);
        set_bit(visible, at, shown);
    }
}

/// Queues the clusters `take` of instance `p` (their boxes' union `bounds`, empty when none)
/// for the batch, and grows `dirty` by their screen rectangle.
#[allow(clippy::too_many_arguments)]
fn queue<'a>(
    pending: &mut Vec<Pending<'a>>,
    scratch: &mut Vec<u32>,
    dirty: &mut Option<PixelRect>,
    view: &View,
    p: &Placed,
    mesh: &'a Mesh,
    mc: &'a MeshClusters,
    take: &[bool],
    bounds: Aabb,
) {
    if bounds.is_empty() {
        return;
    }
    let clip = view.clip_from_object(&p.world_from_object);
    gather(pending, scratch, mesh, mc, clip, p.first_item, |c| take[c]);
    if let Some(r) = screen_rect(&clip, &bounds, view.width(), view.height()) {
        *dirty = Some(union_rect(*dirty, r));
    }
}

/// What the second pass found of one cluster.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Found {
    /// Outside the frustum or hidden.
    Hidden,
    /// Not hidden.
    Shown,
    /// Not hidden, and behind its instance's centre (its box's nearest point farther from the
    /// eye than the centre of the instance's box): its pyramid query
    /// ([`Occlusion::whole_box_query`]) is in [`Tested::behind`], asked again once the front
    /// of its window is drawn. `Found::Shown` when the query needed no pyramid.
    Behind,
}

/// What the second pass found of one instance: `None` when its box is hidden whole, else
/// each cluster's [`Found`].
struct Tested {
    found: Option<Vec<Found>>,
    /// The clusters [`Found::Behind`], with their queries (rectangle, nearest depth).
    behind: Vec<(u32, PixelRect, f32)>,
    /// Groups of clusters tested ([`MeshClusters::groups`]), and those found hidden.
    group_tests: u64,
    groups_hidden: u64,
}

/// Tests one instance's box, then, unless it is hidden, each of its clusters (the frustum
/// first, skipped for an instance wholly inside it; then the face test). With `behind`, the
/// clusters behind the instance's centre that are not hidden are [`Found::Behind`].
fn test_instance(
    view: &View,
    occlusion: &Occlusion<'_>,
    p: &Placed,
    mc: &MeshClusters,
    behind: bool,
    groups: bool,
) -> Tested {
    let mut pc = PyramidCounts::default();
    let eye = view.camera().eye;
    if occlusion.box_hidden(&view.clip_from_world(), &p.bounds, eye, &mut pc) {
        return Tested {
            found: None,
            behind: Vec::new(),
            group_tests: 0,
            groups_hidden: 0,
        };
    }
    let clip = view.clip_from_object(&p.world_from_object);
    let eye_object = p.world_from_object.inverse().transform_point3(eye);
    let frustum = view.frustum(&p.world_from_object);
    let inside = frustum.classify_aabb(&view_box(p, mc)) == Containment::Inside;
    let centre = eye_object.distance_squared(mc.bounds.center());
    let hidden = |b: &Aabb, pc: &mut PyramidCounts| -> Result<Option<(PixelRect, f32)>, ()> {
        if !inside && frustum.classify_aabb(b) == Containment::Outside {
            return Err(());
        }
        match occlusion.whole_box_query(&clip, b, eye_object) {
            Err(true) => Err(()),
            Err(false) => Ok(None),
            Ok((r, nearest)) if occlusion.rect_hidden(r, nearest, pc) => Err(()),
            Ok(query) => Ok(Some(query)),
        }
    };
    let mut queries = Vec::new();
    let mut cluster = |c: usize, pc: &mut PyramidCounts| {
        let b = &mc.boxes[c];
        match hidden(b, pc) {
            Err(()) => Found::Hidden,
            Ok(Some((r, nearest)))
                if behind && eye_object.clamp(b.min, b.max).distance_squared(eye_object) > centre =>
            {
                queries.push((c as u32, r, nearest));
                Found::Behind
            }
            Ok(_) => Found::Shown,
        }
    };
    let (mut group_tests, mut groups_hidden) = (0, 0);
    let found = if !groups || mc.groups.is_empty() {
        (0..mc.len()).map(|c| cluster(c, &mut pc)).collect()
    } else {
        // Down the groups from the top level: a group hidden leaves its clusters hidden.
        let mut found = vec![Found::Hidden; mc.len()];
        let top = mc.groups.len();
        let mut stack: Vec<(usize, usize)> = (0..mc.groups[top - 1].len()).rev().map(|i| (top, i)).collect();
        while let Some((level, i)) = stack.pop() {
            if level == 0 {
                let c = mc.order[i] as usize;
                found[c] = cluster(c, &mut pc);
                continue;
            }
            group_tests += 1;
            if hidden(&mc.groups[level - 1][i], &mut pc).is_err() {
                groups_hidden += 1;
                continue;
            }
            let below = if level == 1 {
                mc.len()
            } else {
                mc.groups[level - 2].len()
            };
            stack.extend((GROUP * i..(GROUP * (i + 1)).min(below)).rev().map(|j| (level - 1, j)));
        }
        found
    };
    Tested {
        found: Some(found),
        behind: queries,
        group_tests,
        groups_hidden,
    }
}

/// Clusters of one instance found [`Found::Behind`], with their queries.
struct Deferred {
    /// Index into the flattened instances.
    instance: u32,
    clusters: Vec<(u32, PixelRect, f32)>,
}

/// The object-space box of an instance's clusters.
fn view_box(_p: &Placed, mc: &MeshClusters) -> Aabb {
    mc.bounds
}

impl Renderer for ClusterCulling {
    fn name(&self) -> &'static str {
        "clusters"
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        crate::check_frame(view, frame)?;
        let start = Instant::now();
        if let Some(direct) = &mut self.direct {
            if let Some(stats) = direct.render_if_due(&mut self.raster, view, frame)? {
                return crate::end_frame(&self.raster, stats);
            }
        }
        let mut stats = self.cull_frame(view, frame)?;
        if let Some(direct) = &mut self.direct {
            // The tests paid when drawing what they removed would have cost more than they
            // did, at this frame's cost of a triangle.
            let t = Instant::now();
            let raster = stats.phases.get(Phase::Raster).as_nanos() as f64;
            let ns = raster / stats.triangles_submitted.max(1) as f64;
            let removed = stats.counters.get("removed_triangles") as f64;
            let cost = (stats.phases.get(Phase::Cull) + stats.phases.get(Phase::DepthStructure)).as_nanos() as f64;
            direct.culled(view, frame, start.elapsed(), &mut stats, removed * ns > cost)?;
            stats.phases.add(Phase::Other, t.elapsed());
        }
        stats.total = start.elapsed();
        crate::end_frame(&self.raster, stats)
    }

    /// The rasterizer's private frames, the pyramid, the direct frames' screening pyramid.
    fn prepare(&mut self, width: u32, height: u32) -> Result<()> {
        crate::prepare_raster(&mut self.raster, &self.scene, width, height);
        crate::sized_pyramid(&mut self.pyramid, width, height)?;
        if let Some(direct) = &mut self.direct {
            direct.prepare(&mut self.raster, width, height)?;
        }
        Ok(())
    }

    fn memory_bytes(&self) -> usize {
        self.raster.memory_bytes()
            + self
                .clusters
                .iter()
                .flatten()
                .map(MeshClusters::memory_bytes)
                .sum::<usize>()
            + self.placed.capacity() * std::mem::size_of::<Placed>()
            + self.visible.capacity() * 8
            + self.pyramid.as_ref().map_or(0, ZPyramid::memory_bytes)
            + self.direct.as_ref().map_or(0, DirectFrames::memory_bytes)
    }
}

impl ClusterCulling {
    /// Draws a culled frame (the module doc's passes 1 to 3).
    fn cull_frame(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        let (start, t, mut stats) = crate::begin_frame(&mut self.raster, view, frame)?;
        let (w, h) = (frame.width(), frame.height());
        if !self.pyramid.as_ref().is_some_and(|p| p.width() == w && p.height() == h) {
            self.pyramid = Some(ZPyramid::new(w, h)?);
        }
        let Self {
            scene,
            raster,
            options,
            clusters,
            placed,
            visible,
            pyramid,
            direct: _,
            precision,
            last_first,
            choice,
            group_rates,
        } = self;
        // The first pass only while last frame's set was mostly still visible: where the view
        // jumps (a cut, a street corner), it would draw what is hidden now.
        let use_first = options.temporal && *precision >= options.trust && !(options.weigh && choice.skip());
        let scene: &Scene = scene;
        let pyramid = pyramid.as_mut().expect("made above");
        let eye = view.camera().eye;
        // The instances in view, nearest box point first.
        let world = view.frustum(&Affine3A::IDENTITY);
        let mut order: Vec<(f32, u32)> = placed
            .iter()
            .enumerate()
            .filter(|(_, p)| world.classify_aabb(&p.bounds) != Containment::Outside)
            .map(|(i, p)| (eye.clamp(p.bounds.min, p.bounds.max).distance_squared(eye), i as u32))
            .collect();
        order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        stats.nodes_visited += order.len() as u64;
        let in_view: u64 = order
            .iter()
            .map(|&(_, i)| scene.node(placed[i as usize].node).item_count())
            .sum();
        stats.phases.add(Phase::Cull, t.elapsed());

        // 1. Last frame's visible clusters, untested.
        let mut first = 0u64;
        let mut pending: Vec<Pending<'_>> = Vec::new();
        let mut scratch: Vec<u32> = Vec::new();
        if use_first {
            let t = Instant::now();
            for &(_, i) in &order {
                let p = &placed[i as usize];
                let (NodeKind::Mesh(mesh), Some(mc)) = (scene.node(p.node).kind(), &clusters[p.node.index()]) else {
                    continue;
                };
                let any = (0..mc.len() as u64).any(|c| bit(visible, p.base + c));
                if any {
                    let clip = view.clip_from_object(&p.world_from_object);
                    first += gather(&mut pending, &mut scratch, mesh, mc, clip, p.first_item, |c| {
                        bit(visible, p.base + c as u64)
                    });
                }
            }
            stats.phases.add(Phase::Cull, t.elapsed());
            draw_pending(raster, view, frame, &mut pending, &mut scratch, &mut stats);
        }
        let t = Instant::now();
        if first > 0 {
            pyramid.rebuild(frame);
        } else {
            pyramid.clear_for(frame);
        }
        stats.phases.add(Phase::DepthStructure, t.elapsed());
        crate::check_cancel(raster)?;

        // 2. Front to back: windows of instances tested in parallel against the pyramid as it
        // stands, their clusters not hidden drawn as one batch, the pyramid updated over it.
        let mut counts = PassCounts::default();
        // A first pass that drew much has left a nearly complete depth: the rest can go in
        // large batches at once.
        let mut budget = options.batch.max(first / 4).min(MAX_BATCH.max(options.batch));
        let mut cull_time = std::time::Duration::ZERO;
        let mut next = 0;
        // Clusters of the last window behind their instances' centres: asked again once the
        // window's front is drawn, with the next window's tests, and drawn in its batch.
        let mut deferred: Vec<Deferred> = Vec::new();
        while next < order.len() || !deferred.is_empty() {
            let t = Instant::now();
            // The window: instances until their triangles reach the budget.
            let mut end = next;
            let mut candidates = 0u64;
            while end < order.len() && candidates < budget {
                let p = &placed[order[end].1 as usize];
                candidates += scene.node(p.node).item_count();
                end += 1;
            }
            let window = &order[next..end];
            next = end;
            let occlusion = Occlusion::hierarchical(frame, pyramid, view);
            let (tested, again): (Vec<Tested>, Vec<Vec<bool>>) = {
                let placed: &[Placed] = placed;
                let clusters: &[Option<MeshClusters>] = clusters;
                let occlusion = &occlusion;
                let deferred = &deferred;
                let group_rates: &[GroupRate] = group_rates;
                let use_groups = options.groups;
                let behind = options.behind;
                raster.install(|| {
                    rayon::join(
                        || {
                            window
                                .par_iter()
                                .map(|&(_, i)| {
                                    let p = &placed[i as usize];
                                    let mc = clusters[p.node.index()]
                                        .as_ref()
                                        .expect("placed instances have clusters");
                                    let groups = use_groups && group_rates[p.node.index()].pays();
                                    test_instance(view, occlusion, p, mc, behind, groups)
                                })
                                .collect()
                        },
                        || {
                            deferred
                                .par_iter()
                                .map(|d| {
                                    let mut pc = PyramidCounts::default();
                                    d.clusters
                                        .iter()
                                        .map(|&(_, r, nearest)| !occlusion.rect_hidden(r, nearest, &mut pc))
                                        .collect()
                                })
                                .collect()
                        },
                    )
                })
            };
            let mut dirty: Option<PixelRect> = None;
            // Last window's clusters behind their centres: those still not hidden.
            for (d, again) in deferred.drain(..).zip(again) {
                let p = &placed[d.instance as usize];
                let (NodeKind::Mesh(mesh), Some(mc)) = (scene.node(p.node).kind(), &clusters[p.node.index()]) else {
                    continue;
                };
                let mut bounds = Aabb::EMPTY;
                let mut take = vec![false; mc.len()];
                for (&(c, _, _), shown) in d.clusters.iter().zip(again) {
                    counts.record(visible, p.base + c as u64, shown);
                    if shown {
                        take[c as usize] = true;
                        bounds = bounds.union(mc.boxes[c as usize]);
                    }
                }
                queue(&mut pending, &mut scratch, &mut dirty, view, p, mesh, mc, &take, bounds);
            }
            for (&(_, i), tested) in window.iter().zip(tested) {
                let p = &placed[i as usize];
                let (NodeKind::Mesh(mesh), Some(mc)) = (scene.node(p.node).kind(), &clusters[p.node.index()]) else {
                    continue;
                };
                counts.tested += 1;
                counts.groups += tested.group_tests;
                let Some(found) = tested.found else {
                    counts.instances_culled += 1;
                    for c in 0..mc.len() as u64 {
                        counts.was_visible += u64::from(bit(visible, p.base + c));
                        set_bit(visible, p.base + c, false);
                    }
                    continue;
                };
                counts.tested += found.len() as u64;
                group_rates[p.node.index()].record(tested.group_tests, tested.groups_hidden);
                let mut bounds = Aabb::EMPTY;
                let mut take = vec![false; mc.len()];
                for (c, f) in found.into_iter().enumerate() {
                    let at = p.base + c as u64;
                    let was = bit(visible, at);
                    let shown = match f {
                        Found::Hidden => false,
                        Found::Shown => true,
                        // Drawn by the first pass already: nothing to wait for.
                        Found::Behind if was && use_first => true,
                        // Waits (below): its bit stays last frame's until it is asked again.
                        Found::Behind => continue,
                    };
                    counts.record(visible, at, shown);
                    if shown && !(was && use_first) {
                        take[c] = true;
                        bounds = bounds.union(mc.boxes[c]);
                    }
                }
                let later: Vec<(u32, PixelRect, f32)> = tested
                    .behind
                    .into_iter()
                    .filter(|&(c, _, _)| !(use_first && bit(visible, p.base + c as u64)))
                    .collect();
                if !later.is_empty() {
                    counts.deferred += later.len() as u64;
                    deferred.push(Deferred {
                        instance: i,
                        clusters: later,
                    });
                }
                queue(&mut pending, &mut scratch, &mut dirty, view, p, mesh, mc, &take, bounds);
            }
            cull_time += t.elapsed();
            if !pending.is_empty() {
                draw_pending(raster, view, frame, &mut pending, &mut scratch, &mut stats);
                counts.batches += 1;
                let u = Instant::now();
                // Only where the batch wrote: the clusters' region cut to the box of the
                // triangles that wrote a fragment.
                let written = crate::written_region(raster, view);
                if let (Some(d), true) = (
                    dirty.zip(written).and_then(|(d, w)| d.intersect(&w)),
                    next < order.len() || !deferred.is_empty(),
                ) {
                    pyramid.update(frame, d);
                }
                stats.phases.add(Phase::DepthStructure, u.elapsed());
                crate::check_cancel(raster)?;
            }
            budget = (budget * 2).min(MAX_BATCH.max(options.batch));
        }
        stats.phases.add(Phase::Cull, cull_time);
        // A frame drawn without the first pass leaves as visible every cluster its tests could
        // not hide against depth still being drawn, more than are: the next frame's share
        // would then be low because of it, and is not taken.
        if counts.was_visible > 0 && (*last_first || !use_first) {
            *precision = counts.still_visible as f64 / counts.was_visible as f64;
        }
        // A first pass drawn from a frame without one holds clusters that frame could not hide
        // (above): not what the first pass costs, so not recorded (a probe of it then lasts
        // two frames).
        let measured = *last_first || first == 0;
        // Drew: a first pass with nothing of last frame's set in view drew none.
        *last_first = use_first && first > 0;
        if options.temporal && options.weigh && measured {
            choice.record(first > 0, start.elapsed());
        }
        stats.boxes_tested += counts.tested;
        stats.boxes_culled += counts.culled + counts.instances_culled;
        stats.counters.add_all([
            ("clusters_tested", counts.tested),
            ("clusters_culled", counts.culled),
            ("instances_culled", counts.instances_culled),
            ("first_triangles", first),
            ("batches", counts.batches),
            ("removed_triangles", in_view.saturating_sub(stats.triangles_submitted)),
            ("precision_pct", (100.0 * *precision).round() as u64),
            ("clusters_deferred", counts.deferred),
            ("group_tests", counts.groups),
        ]);
        stats.total = start.elapsed();
        Ok(stats)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every triangle in exactly one cluster, each cluster at most `size` triangles in
    /// ascending order and inside its box.
    fn check(mesh: &Mesh, size: usize) -> MeshClusters {
        let mc = MeshClusters::build(mesh, size).expect("a valid mesh clusters");
        let mut seen = vec![0u32; mesh.triangle_count()];
        for c in 0..mc.len() {
            let tris = mc.meshlets.triangles(c);
            assert!(
                !tris.is_empty() && tris.len() <= size,
                "cluster {c}: {} triangles",
                tris.len()
            );
            assert!(tris.windows(2).all(|w| w[0] < w[1]), "cluster {c} not ascending");
            for &t in tris {
                seen[t as usize] += 1;
                for p in mesh.triangle_positions(t as usize) {
                    assert!(
                        mc.boxes[c].contains_point(p),
                        "cluster {c}: triangle {t} outside its box"
                    );
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1), "a triangle in no cluster or in several");
        // The groups: over a permutation of the clusters, each level bounding the one below,
        // up to at most GROUP boxes.
        let mut order = mc.order.clone();
        order.sort_unstable();
        assert!(order.iter().copied().eq(0..mc.len() as u32));
        assert_eq!(mc.groups.is_empty(), mc.len() <= GROUP);
        let mut below: Vec<Aabb> = mc.order.iter().map(|&c| mc.boxes[c as usize]).collect();
        for (level, boxes) in mc.groups.iter().enumerate() {
            assert_eq!(boxes.len(), below.len().div_ceil(GROUP), "level {level}");
            for (i, g) in boxes.iter().enumerate() {
                for b in &below[GROUP * i..(GROUP * (i + 1)).min(below.len())] {
                    assert!(
                        g.contains_point(b.min) && g.contains_point(b.max),
                        "level {level} group {i}"
                    );
                }
            }
            below = boxes.clone();
        }
        assert!(mc.groups.last().is_none_or(|top| top.len() <= GROUP));
        mc
    }

    #[test]
    fn groups_are_tested_while_they_are_found_hidden() {
        let mut rate = GroupRate::default();
        assert!(rate.pays(), "tested until the rate is known");
        rate.record(20, 1);
        assert!(!rate.pays(), "one group in twenty hidden");
        for _ in 0..GROUP_RETRY - 1 {
            rate.record(0, 0);
            assert!(!rate.pays());
        }
        rate.record(0, 0);
        assert!(rate.pays(), "tested again after {GROUP_RETRY} instances without");
        rate.record(20, 10);
        assert!(rate.pays(), "half of them hidden");
    }

    #[test]
    fn groups_of_clusters_find_what_the_clusters_find() {
        use occult_core::{Instance, SceneBuilder};
        // A grid of 8,192 triangles (128 clusters under two levels of groups), its lower half
        // hidden behind a copy nearer the eye.
        let mut b = SceneBuilder::new();
        let grid = b.add_mesh("grid", crate::test_grid(64)).expect("a mesh node");
        let placed = |at: Vec3| Instance {
            parent_from_child: Affine3A::from_translation(at),
            child: grid,
        };
        let root = b
            .add_group(
                "two",
                vec![placed(Vec3::new(-0.5, -0.5, 0.0)), placed(Vec3::new(-0.5, -1.0, 0.5))],
            )
            .expect("a group of the grid");
        let scene = Arc::new(b.build(root).expect("a scene"));
        let r = ClusterCulling::new(scene.clone(), &RenderOptions::default(), &ClusterOptions::default())
            .expect("clusters build");
        // From afar, all in view; and from near, the frustum cutting the grids.
        for eye in [Vec3::new(0.0, 0.0, 2.0), Vec3::new(0.3, -0.2, 0.9)] {
            let (view, _) = crate::test_view(eye, Vec3::new(eye.x, eye.y, 0.0), 96, 64);
            let frame = crate::tests::zbuffer_frame(&scene, &view);
            let mut pyramid = ZPyramid::new(96, 64).expect("a pyramid");
            pyramid.rebuild(&frame);
            let occlusion = Occlusion::hierarchical(&frame, &pyramid, &view);
            let (mut hidden, mut shown, mut behind_found) = (0, 0, 0);
            for p in &r.placed {
                let mc = r.clusters[p.node.index()].as_ref().expect("a mesh's clusters");
                assert_eq!(mc.groups.len(), 2);
                for behind in [false, true] {
                    let with = test_instance(&view, &occlusion, p, mc, behind, true);
                    let without = test_instance(&view, &occlusion, p, mc, behind, false);
                    assert_eq!(with.found, without.found, "{eye}, behind {behind}");
                    let mut queries = (with.behind, without.behind);
                    queries.0.sort_unstable_by_key(|q| q.0);
                    assert_eq!(queries.0, queries.1, "{eye}, behind {behind}");
                    behind_found += queries.0.len();
                    assert_eq!(without.group_tests, 0);
                    hidden += with.groups_hidden;
                    shown += with.found.iter().flatten().filter(|f| **f != Found::Hidden).count();
                }
            }
            assert!(
                hidden > 0 && shown > 0 && behind_found > 0,
                "{eye}: {hidden} groups hidden, {shown} clusters not hidden, {behind_found} behind"
            );
        }
    }

    #[test]
    fn clusters_hold_every_triangle_once() {
        let grid = crate::test_grid(40);
        let mc = check(&grid, 64);
        assert!(mc.len() >= grid.triangle_count().div_ceil(64));
        // Small enough for one cluster.
        assert_eq!(check(&crate::test_grid(4), 64).len(), 1);
        // Duplicated and degenerate triangles (which the clusterizer may leave out) too.
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let mut triangles = vec![[0, 1, 2]; 30];
        triangles.extend([[0, 0, 1]; 20]);
        triangles.extend([[1, 2, 3]; 30]);
        check(&Mesh::new(positions, triangles).expect("indices in range"), 8);
    }

    #[test]
    fn size_and_batch_are_checked() {
        for (size, batch) in [(4, 1), (9, 1), (516, 1), (64, 0)] {
            let co = ClusterOptions {
                size,
                batch,
                ..ClusterOptions::default()
            };
            assert!(co.validate().is_err(), "size {size}, batch {batch}");
        }
        assert!(ClusterOptions::default().validate().is_ok());
    }

    #[test]
    fn too_many_mesh_instances_is_an_error_before_flattening() {
        // 2^12 x 2^11 instances of one small mesh: 2^23 mesh instances, counted, not walked.
        let scene = Arc::new(crate::test_quad_rows(1 << 11, 1 << 12));
        assert_eq!(mesh_instance_count(&scene), 1 << 23);
        let e = ClusterCulling::new(scene, &RenderOptions::default(), &ClusterOptions::default())
            .err()
            .expect("more mesh instances than the renderer flattens");
        assert!(e.to_string().contains("8388608 mesh instances"), "{e}");
    }

    #[test]
    fn direct_frames_are_identical_and_counted() {
        let (scene, view, reference) = crate::direct::tests::scene_view_reference();
        // Windows of one cube (12 triangles): each tested against the cubes drawn before it.
        let co = ClusterOptions {
            batch: 12,
            ..ClusterOptions::default()
        };
        let mut r = ClusterCulling::new(scene, &RenderOptions::default(), &co).expect("clusters build");
        // Culled first (no direct frame measured yet): the row of cubes hides most of those
        // behind it.
        let mut f = Frame::new(96, 64).expect("a 96x64 frame");
        let s = r.render(&view, &mut f).expect("the view renders");
        assert!(f.same_visibility(&reference));
        assert_eq!(s.counters.get(crate::direct::COUNTER), 0);
        assert!(s.counters.get("removed_triangles") > 0);
        r.direct.as_mut().expect("payoff is on by default").force(2, false);
        for i in 0..2 {
            let mut f = Frame::new(96, 64).expect("a 96x64 frame");
            let s = r.render(&view, &mut f).expect("the view renders");
            assert!(f.same_visibility(&reference), "frame {i}");
            assert_eq!(s.counters.get(crate::direct::COUNTER), 1, "frame {i}");
        }
    }
}
