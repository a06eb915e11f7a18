//! Hierarchical view-frustum culling: the baseline every paper compares against.
//!
//! Preprocessing builds a [`Bvh`] per node of the scene DAG: over the triangles of each mesh
//! with more than [`FrustumOptions::mesh_leaf_size`] triangles, and over the instances of each
//! group with more than a few. A frame walks the DAG from the root without flattening it, with
//! the crate's scene walk ([`crate::walk`]): at each node instance it forms the frustum in that
//! node's space (planes of `clip_from_object`), descends the node's hierarchy
//! ([`crate::walk::cull_bvh`]), skips subtrees outside, stops testing inside subtrees wholly
//! inside, and hands the surviving triangles to the rasterizer: whole meshes when entirely
//! inside or mostly kept, else the kept leaves and subtrees as their clusters (each leaf's
//! triangles cut into clusters of at most 256 vertices at build, `crate::runs`, so that
//! their vertices are projected once, as a whole mesh's are; `clusters=off`: index lists).
//!
//! Cost: O(visited nodes + triangles in the frustum). It removes nothing that is in the frustum
//! but hidden; that is the occlusion culling renderers' job.

use std::sync::Arc;
use std::time::Instant;

use occult_core::{NodeKind, Scene, View};
use occult_raster::{Draw, DrawTriangles, Frame, PyramidCounts, Rasterizer, ZPyramid};
use occult_spatial::Bvh;
use rayon::prelude::*;

use crate::hzb::boxtest::Occlusion;
use crate::nodes::{instance_boxes, per_node, triangle_boxes};
use crate::runs::RunClusters;
use crate::walk::{cull_bvh, Counts, NodeAt, SceneWalk, Visitor};
use crate::{AlgorithmInfo, FrameStats, ParamDoc, Phase, RenderError, RenderOptions, Renderer, Result};

/// Tunables of [`FrustumCulling`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrustumOptions {
    /// Triangles per BVH leaf of a mesh (≥ 1): smaller culls finer but visits more nodes.
    pub mesh_leaf_size: usize,
    /// Instances per BVH leaf of a group (≥ 1).
    pub group_leaf_size: usize,
    /// Draws handed to the rasterizer at a time (≥ 1): bounds a frame's memory where many
    /// instances lie in the view (each batch past the first walks the hierarchy again).
    pub batch_draws: usize,
    /// A mesh's leaves kept as clusters of few vertices ([`occult_raster::Meshlets`], about 24
    /// bytes a triangle), drawn as cluster draws, each vertex projected once; off: index
    /// lists, three corners projected a triangle.
    pub clusters: bool,
}

impl Default for FrustumOptions {
    fn default() -> Self {
        Self {
            mesh_leaf_size: 256,
            group_leaf_size: 4,
            batch_draws: 1 << 20,
            clusters: true,
        }
    }
}

impl FrustumOptions {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a zero leaf size or batch.
    pub fn validate(&self) -> Result<()> {
        if self.mesh_leaf_size == 0 || self.group_leaf_size == 0 {
            return Err(RenderError::BadParameter(
                "frustum: leaf sizes must be at least 1".into(),
            ));
        }
        if self.batch_draws == 0 {
            return Err(RenderError::BadParameter("frustum: batch must be at least 1".into()));
        }
        Ok(())
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
        ParamDoc {
            key: "batch",
            default: "1048576",
            help: "draws handed to the rasterizer at a time (>= 1; about 100 bytes each): a frame with more walks the hierarchy again per batch",
        },
        ParamDoc {
            key: "clusters",
            default: "on",
            help: "a mesh's BVH leaves drawn as clusters of few vertices, each vertex projected once (about 24 bytes a triangle); off: index lists",
        },
    ],
    counters: &[],
    conservative: true,
    bands: true,
    build: |scene, options, params| {
        let mut fo = FrustumOptions::default();
        crate::params::read_params!(params, fo, {
            mesh_leaf_size: "leaf",
            group_leaf_size: "group_leaf",
            batch_draws: "batch",
            clusters: flag "clusters",
        });
        Ok(Box::new(FrustumCulling::with_options(scene, options, &fo)?))
    },
};

/// The frustum-culling renderer.
pub struct FrustumCulling {
    culling: Hierarchies,
    raster: Rasterizer,
}

/// What frustum culling keeps of a scene, apart from a rasterizer: the scene, its
/// hierarchies and the batch size. Other renderers embed one to draw frames as `frustum`
/// does, through their own rasterizer ([`crate::direct`]).
pub struct Hierarchies {
    scene: Arc<Scene>,
    /// Per node: its hierarchy (None when small enough to test as one box).
    hierarchies: Vec<Option<Bvh>>,
    /// Per mesh with a hierarchy: its leaves' triangles as clusters, a run per leaf.
    clusters: Vec<Option<RunClusters>>,
    /// [`FrustumOptions::batch_draws`].
    batch_draws: usize,
}

impl FrustumCulling {
    /// Builds the per-node hierarchies of `scene`.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a zero leaf size; raster configuration errors.
    pub fn with_options(scene: Arc<Scene>, options: &RenderOptions, fo: &FrustumOptions) -> Result<Self> {
        let raster = crate::scene_rasterizer(&scene, options)?;
        Ok(Self {
            culling: Hierarchies::build(scene, &raster, fo)?,
            raster,
        })
    }
}

impl Hierarchies {
    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Builds the per-node hierarchies of `scene` (on `raster`'s threads).
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a zero leaf size or batch.
    pub fn build(scene: Arc<Scene>, raster: &Rasterizer, fo: &FrustumOptions) -> Result<Self> {
        fo.validate()?;
        let hierarchies: Vec<Option<Bvh>> = per_node(raster, &scene, |node| match node.kind() {
            NodeKind::Mesh(m) if m.triangle_count() > fo.mesh_leaf_size => {
                Some(Bvh::build(&triangle_boxes(m), fo.mesh_leaf_size))
            }
            NodeKind::Group(g) if g.len() > fo.group_leaf_size => {
                Some(Bvh::build(&instance_boxes(&scene, g), fo.group_leaf_size))
            }
            _ => None,
        });
        let clusters = scene
            .nodes()
            .iter()
            .zip(&hierarchies)
            .map(|(node, h)| match (node.kind(), h.as_ref()) {
                (NodeKind::Mesh(m), Some(bvh)) if fo.clusters => leaf_clusters(m, bvh).map(Some),
                _ => Ok(None),
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            scene,
            hierarchies,
            clusters,
            batch_draws: fo.batch_draws,
        })
    }

    /// The triangles a frame of `view` submits, found by one walk of the hierarchies that
    /// draws nothing: the work [`crate::direct`] measures frames by.
    pub fn triangles_in_view(&self, view: &View) -> u64 {
        let mut w = Walk::new(self, view, 0, 0);
        w.run();
        w.walk.triangles_met()
    }

    /// Draws a frame of `view` into `frame` (cleared first) through `raster`: what
    /// [`FrustumCulling`] renders.
    ///
    /// # Errors
    /// A frame whose size is not the view's; a view of more triangles than a frame can draw
    /// ([`RenderError::TooManyInView`]).
    pub fn render(&self, raster: &mut Rasterizer, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        let (start, t, cleared) = crate::begin_frame(raster, view, frame)?;
        // The first walk meets every draw (keeping the first batch) and gives the statistics.
        let mut first = Walk::new(self, view, 0, self.batch_draws);
        first.walk.stats = cleared;
        first.run();
        let Walk {
            walk,
            mut draws,
            met,
            mut more,
            ..
        } = first;
        let triangles = walk.triangles_met();
        let mut stats = walk.finish("frustum")?;
        stats.phases.add(Phase::Cull, t.elapsed());
        let mut done = 0;
        loop {
            // Progress: triangles submitted of those the first walk met.
            let before = stats.triangles_submitted;
            crate::rasterize_counted(raster, view, frame, &draws, &mut stats, Some((before, triangles)));
            crate::check_cancel(raster)?;
            done += draws.len();
            if !more {
                break;
            }
            let t = Instant::now();
            let mut next = Walk::new(self, view, done, self.batch_draws);
            next.run();
            stats.phases.add(Phase::Cull, t.elapsed());
            (draws, more) = (next.draws, next.more);
        }
        debug_assert_eq!((done, stats.triangles_submitted), (met, triangles));
        stats.total = start.elapsed();
        // Not `end_frame`: a culling renderer's direct frame is part of its frame.
        crate::check_cancel(raster)?;
        Ok(stats)
    }

    /// Bytes held by the hierarchies and their clusters.
    pub fn memory_bytes(&self) -> usize {
        self.hierarchies.iter().flatten().map(Bvh::memory_bytes).sum::<usize>()
            + self
                .clusters
                .iter()
                .flatten()
                .map(RunClusters::memory_bytes)
                .sum::<usize>()
    }

    /// The triangles in the view of `frame` (drawn whole, its depth final) whose boxes are
    /// hidden behind that depth: what a frustum walk meets that an occlusion test of its boxes
    /// (Greene's §3.2 face test through `pyramid`, rebuilt here from the frame) would remove
    /// with every occluder already drawn. No culling renderer's frame of the view removes more
    /// at this granularity, drawing occluders first as it must ([`crate::direct`] screens its
    /// probes with it).
    ///
    /// The groups are walked on the calling thread; the mesh occurrences met, each a descent
    /// of its mesh's hierarchy (nearly all the boxes), are then shared over `pool`'s threads
    /// (the caller's pool when `None`). Beyond twice [`HIDDEN_SAMPLED_MESHES`] occurrences,
    /// the count is an estimate leaning high, in culling's favour as the screenings use it:
    /// every occurrence holding at least a [`HIDDEN_SAMPLED_MESHES`]-th of their triangles is
    /// descended, and of the others a stride of about [`HIDDEN_SAMPLED_MESHES`]; their share of
    /// hidden triangles, raised by [`HIDDEN_LEAN`] standard errors, stands for all the others.
    /// The count does not depend on the threads.
    pub fn hidden_triangles(
        &self,
        view: &View,
        frame: &Frame,
        pyramid: &mut ZPyramid,
        pool: Option<&rayon::ThreadPool>,
    ) -> u64 {
        self.hidden_triangles_sampling(view, frame, pyramid, pool, HIDDEN_SAMPLED_MESHES)
            .hidden
    }

    /// [`Hierarchies::hidden_triangles`], sampling beyond twice `sampled` mesh occurrences
    /// (`usize::MAX`: the exact count).
    fn hidden_triangles_sampling(
        &self,
        view: &View,
        frame: &Frame,
        pyramid: &mut ZPyramid,
        pool: Option<&rayon::ThreadPool>,
        sampled: usize,
    ) -> HiddenCount {
        pyramid.rebuild(frame);
        let pyramid: &ZPyramid = pyramid;
        let mut w = Hidden {
            walk: SceneWalk::new(&self.scene, view),
            hierarchies: &self.hierarchies,
            occlusion: Occlusion::hierarchical(frame, pyramid, view),
            counts: PyramidCounts::default(),
            hidden: 0,
            meshes: Vec::new(),
        };
        w.run();
        let (hidden, meshes) = (w.hidden, w.meshes);
        let met = meshes.len();
        let sample = MeshSample::of(meshes, sampled);
        let hierarchies = &self.hierarchies;
        let occlusion = Occlusion::hierarchical(frame, pyramid, view);
        let in_meshes = || {
            sample
                .descended
                .par_chunks(HIDDEN_MESHES_PER_TASK)
                .map(|chunk| {
                    let mut m = MeshHidden::default();
                    chunk
                        .iter()
                        .map(|at| {
                            let before = m.hidden;
                            if let Some(bvh) = &hierarchies[at.place.id.index()] {
                                m.descend(&occlusion, view, at, bvh);
                            }
                            m.hidden - before
                        })
                        .collect::<Vec<u64>>()
                })
                .collect::<Vec<_>>()
                .concat()
        };
        let counts = pool.map_or_else(in_meshes, |p| p.install(in_meshes));
        HiddenCount {
            hidden: hidden + sample.estimate(&counts),
            met,
            descended: sample.descended.len(),
        }
    }
}

/// What [`Hierarchies::hidden_triangles`] found, and how many mesh occurrences it met and
/// descended (tests).
struct HiddenCount {
    hidden: u64,
    #[cfg_attr(not(test), allow(dead_code))]
    met: usize,
    #[cfg_attr(not(test), allow(dead_code))]
    descended: usize,
}

/// The mesh occurrences [`Hierarchies::hidden_triangles`] descends: all, or those counted
/// exactly (the large ones) followed by a systematic sample of the rest.
struct MeshSample<'a> {
    descended: Vec<NodeAt<'a>>,
    /// How many of `descended`, from the first, are counted exactly.
    exact: usize,
    /// The triangles and the number of the occurrences the sample stands for (the rest).
    rest: (u64, usize),
}

impl<'a> MeshSample<'a> {
    /// All of `meshes` up to twice `sampled`; beyond, those holding at least a `sampled`-th of
    /// all their triangles, and a stride of the rest starting halfway into the first stride
    /// (the walk's order follows the scene's hierarchies: not always its first occurrence).
    fn of(meshes: Vec<NodeAt<'a>>, sampled: usize) -> Self {
        let sampled = sampled.max(1);
        if meshes.len() <= sampled.saturating_mul(2) {
            return Self {
                exact: meshes.len(),
                descended: meshes,
                rest: (0, 0),
            };
        }
        let all: u64 = meshes.iter().map(|at| at.node.item_count()).sum();
        let large = all / sampled as u64;
        let (mut descended, rest): (Vec<_>, Vec<_>) = meshes.into_iter().partition(|at| at.node.item_count() >= large);
        let exact = descended.len();
        let stride = (rest.len() / sampled).max(1);
        let rest_items = rest.iter().map(|at| at.node.item_count()).sum();
        let rest_len = rest.len();
        descended.extend(rest.into_iter().skip(stride / 2).step_by(stride));
        Self {
            descended,
            exact,
            rest: (rest_items, rest_len),
        }
    }

    /// The hidden triangles of every occurrence from `counts`, those of the descended ones in
    /// order: the exact ones' own, and for the rest the sampled ones' share of hidden
    /// triangles (a ratio estimate) raised by [`HIDDEN_LEAN`] standard errors, at most all of
    /// the rest.
    fn estimate(&self, counts: &[u64]) -> u64 {
        let exact: u64 = counts[..self.exact].iter().sum();
        let (rest_items, rest_len) = self.rest;
        let pairs: Vec<(f64, f64)> = self.descended[self.exact..]
            .iter()
            .zip(&counts[self.exact..])
            .map(|(at, &h)| (h as f64, at.node.item_count() as f64))
            .collect();
        if rest_len == pairs.len() {
            return exact + counts[self.exact..].iter().sum::<u64>();
        }
        exact + (upper_share(&pairs, rest_len, HIDDEN_LEAN) * rest_items as f64).ceil() as u64
    }
}

/// The share of triangles hidden over a population of `population` occurrences, from a
/// sample of `(hidden, triangles)` pairs: the ratio of the sums raised by `lean` standard
/// errors of the ratio estimator (with the finite population correction), at most 1.
fn upper_share(pairs: &[(f64, f64)], population: usize, lean: f64) -> f64 {
    let n = pairs.len() as f64;
    let (hidden, items) = pairs.iter().fold((0.0, 0.0), |(h, w), p| (h + p.0, w + p.1));
    if n < 2.0 || items <= 0.0 {
        return 1.0;
    }
    let ratio = hidden / items;
    let spread = pairs.iter().map(|&(h, w)| (h - ratio * w).powi(2)).sum::<f64>() / (n - 1.0);
    let correction = (1.0 - n / population.max(1) as f64).max(0.0);
    let error = (correction * spread / n).sqrt() / (items / n);
    (ratio + lean * error).min(1.0)
}

/// Mesh occurrences [`Hierarchies::hidden_triangles`] descends beyond twice this many: about
/// this many of the smaller ones, and every large one (each descent visits nearly all of its
/// mesh's boxes; on a scene of many instances the descents are nearly all of a screening).
/// Measured on `city:blocks=32` from outside (3,600-4,100 occurrences in view), the estimate
/// came within -2 to +5 % of the exact count with 256 (and [`HIDDEN_LEAN`]), against +2 to
/// +28 % with 64 and two standard errors: a screening's decision is a threshold that views
/// near it would cross by the error.
const HIDDEN_SAMPLED_MESHES: usize = 256;

/// Standard errors the sampled share of hidden triangles is raised by
/// ([`Hierarchies::hidden_triangles`]): leaning in culling's favour without making every
/// sampled view look more hidden than its screenings' thresholds allow (two made `nbuffer`'s
/// first frame of `city:blocks=32` from outside, 3.48 M hidden of 29.5 M by the exact count
/// against a threshold of 3.68 M, run its tests and lose).
const HIDDEN_LEAN: f64 = 1.0;

/// Mesh occurrences one task of [`Hierarchies::hidden_triangles`] descends (a few hundred
/// boxes each: a task of tens of microseconds).
const HIDDEN_MESHES_PER_TASK: usize = 16;

/// Most clusters in one draw of a kept subtree: the rasterizer finds where a range of a draw's
/// triangles begins by a walk of its clusters, once per range of a shared draw (2,048 triangles),
/// so one draw of a large subtree's clusters would cost the square of its size.
const DRAW_CLUSTERS: usize = 64;

/// The triangles of the leaves of `bvh`, a hierarchy of `mesh`, as clusters, a run per leaf
/// (leaves in the order of their entries, so that a subtree's entries are consecutive runs).
fn leaf_clusters(mesh: &occult_core::Mesh, bvh: &Bvh) -> Result<RunClusters> {
    let mut starts: Vec<u32> = bvh.nodes().iter().filter(|n| n.is_leaf()).map(|n| n.first).collect();
    starts.sort_unstable();
    starts.push(bvh.primitive_indices().len() as u32);
    RunClusters::build(mesh, bvh.primitive_indices(), starts)
}

/// The walk of [`Hierarchies::hidden_triangles`]: the frustum walk, each box also tested
/// against the final depth; the mesh occurrences with a hierarchy kept for
/// [`MeshHidden::descend`].
struct Hidden<'a> {
    walk: SceneWalk<'a>,
    hierarchies: &'a [Option<Bvh>],
    occlusion: Occlusion<'a>,
    counts: PyramidCounts,
    /// Triangle instances under the hidden boxes met so far: of the groups' hierarchies, and
    /// of the node occurrences whose own box is hidden.
    hidden: u64,
    /// The mesh occurrences met, their own box not hidden.
    meshes: Vec<NodeAt<'a>>,
}

impl Counts for Hidden<'_> {
    fn counts(&mut self) -> &mut FrameStats {
        &mut self.walk.stats
    }
}

impl<'a> Visitor<'a> for Hidden<'a> {
    fn walk(&mut self) -> &mut SceneWalk<'a> {
        &mut self.walk
    }

    fn visit(&mut self, at: &NodeAt<'a>) {
        let view = self.walk.view();
        let clip = view.clip_from_object(&at.place.world_from_node);
        let eye = at.place.world_from_node.inverse().transform_point3(view.camera().eye);
        if self
            .occlusion
            .box_hidden(&clip, &at.node.bounds(), eye, &mut self.counts)
        {
            self.hidden += at.node.item_count();
            return;
        }
        let scene = self.walk.scene();
        let hierarchy = self.hierarchies[at.place.id.index()].as_ref();
        match (at.node.kind(), hierarchy) {
            (NodeKind::Mesh(_), Some(_)) => self.meshes.push(*at),
            (NodeKind::Mesh(_), None) => {}
            (NodeKind::Group(instances), Some(bvh)) => cull_bvh(self, bvh, &at.frustum, |w, _, bn, inside| {
                let under = &bvh.primitive_indices()[bn.range()];
                if w.occlusion.box_hidden(&clip, &bn.bounds, eye, &mut w.counts) {
                    w.hidden += under
                        .iter()
                        .map(|&i| scene.node(instances[i as usize].child).item_count())
                        .sum::<u64>();
                    return false;
                }
                if bn.is_leaf() {
                    for &i in under {
                        w.enter(at.child(i as usize), inside);
                    }
                }
                true
            }),
            (NodeKind::Group(instances), None) => {
                for i in 0..instances.len() {
                    self.enter(at.child(i), at.inside);
                }
            }
        }
    }
}

/// One task's share of [`Hierarchies::hidden_triangles`]: the descents of mesh hierarchies.
#[derive(Default)]
struct MeshHidden {
    stats: FrameStats,
    counts: PyramidCounts,
    /// Triangle instances under the hidden boxes.
    hidden: u64,
}

impl Counts for MeshHidden {
    fn counts(&mut self) -> &mut FrameStats {
        &mut self.stats
    }
}

impl MeshHidden {
    /// The frustum-culled descent of `bvh`, the hierarchy of the mesh occurrence `at`, adding
    /// the triangles under its hidden boxes.
    fn descend(&mut self, occlusion: &Occlusion<'_>, view: &View, at: &NodeAt<'_>, bvh: &Bvh) {
        let clip = view.clip_from_object(&at.place.world_from_node);
        let eye = at.place.world_from_node.inverse().transform_point3(view.camera().eye);
        cull_bvh(self, bvh, &at.frustum, |m, _, bn, _| {
            if occlusion.box_hidden(&clip, &bn.bounds, eye, &mut m.counts) {
                m.hidden += bn.range().len() as u64;
                return false;
            }
            true
        });
    }
}

/// Per-frame traversal state: the scene walk, and the draws of this walk's batch.
struct Walk<'a> {
    walk: SceneWalk<'a>,
    hierarchies: &'a [Option<Bvh>],
    clusters: &'a [Option<RunClusters>],
    /// Draws of this walk's batch: those after the first `skip` in traversal order, at most
    /// `cap` of them.
    draws: Vec<Draw<'a>>,
    skip: usize,
    cap: usize,
    /// Draws met so far in traversal order.
    met: usize,
    /// Draws met beyond the batch.
    more: bool,
    /// Entries (of the hierarchy's primitive indices) of the leaves and subtrees kept in the
    /// mesh being walked.
    leaves: Vec<std::ops::Range<usize>>,
}

impl<'a> Walk<'a> {
    /// A walk that keeps the draws after the first `skip`, at most `cap` of them.
    fn new(h: &'a Hierarchies, view: &'a View, skip: usize, cap: usize) -> Self {
        Self {
            walk: SceneWalk::new(&h.scene, view),
            hierarchies: &h.hierarchies,
            clusters: &h.clusters,
            draws: Vec::new(),
            skip,
            cap,
            met: 0,
            more: false,
            leaves: Vec::new(),
        }
    }

    /// Meets `triangles` triangles in a walk that keeps no draws (`cap` 0: counting only).
    fn draw_none(&mut self, triangles: usize) {
        self.walk.meet_triangles(triangles as u64);
        self.met += 1;
        self.more |= self.met > self.skip;
    }

    /// Meets a draw of `triangles` triangles, in traversal order.
    fn draw(&mut self, draw: Draw<'a>, triangles: usize) {
        self.walk.meet_triangles(triangles as u64);
        self.met += 1;
        if self.met <= self.skip {
            return;
        }
        if self.draws.len() < self.cap {
            self.draws.push(draw);
        } else {
            self.more = true;
        }
    }
}

impl Counts for Walk<'_> {
    fn counts(&mut self) -> &mut FrameStats {
        &mut self.walk.stats
    }
}

impl<'a> Visitor<'a> for Walk<'a> {
    fn walk(&mut self) -> &mut SceneWalk<'a> {
        &mut self.walk
    }

    /// A mesh: whole when inside or small, else the leaves of its BVH in the frustum. A group:
    /// the instances in the leaves of its BVH in the frustum (all of them when inside).
    fn visit(&mut self, at: &NodeAt<'a>) {
        let hierarchies: &'a [Option<Bvh>] = self.hierarchies;
        let hierarchy = hierarchies[at.place.id.index()].as_ref();
        match at.node.kind() {
            NodeKind::Mesh(mesh) => {
                if mesh.triangle_count() == 0 {
                    return;
                }
                let whole = Draw {
                    mesh,
                    triangles: DrawTriangles::All,
                    clip_from_object: self.walk.view().clip_from_object(&at.place.world_from_node),
                    first_item: at.place.first_item,
                };
                let bvh = match (hierarchy, at.inside) {
                    (Some(bvh), false) => bvh,
                    _ => return self.draw(whole, mesh.triangle_count()),
                };
                let mut leaves = std::mem::take(&mut self.leaves);
                leaves.clear();
                let mut kept = 0usize;
                cull_bvh(self, bvh, &at.frustum, |_, _, bn, inside| {
                    if inside || bn.is_leaf() {
                        kept += bn.range().len();
                        leaves.push(bn.range());
                        return false;
                    }
                    true
                });
                // The kept leaves and subtrees draw as their clusters, whose vertices are
                // projected once each, about as a whole mesh's are. When most of the mesh
                // survived, drawing it whole is cheaper still (the rasterizer's outcode test
                // drops the rest at a few ns each).
                let clusters: &'a [Option<RunClusters>] = self.clusters;
                let clusters = clusters[at.place.id.index()].as_ref();
                if kept * 2 > mesh.triangle_count() {
                    self.draw(whole, mesh.triangle_count());
                } else {
                    for range in leaves.drain(..) {
                        if self.cap == 0 {
                            self.draw_none(range.len()); // counting only
                            continue;
                        }
                        match clusters.and_then(|c| c.entries(range.clone())) {
                            // A subtree's clusters in draws of at most `DRAW_CLUSTERS` (the
                            // rasterizer finds a range's first triangle by a walk of its draw's
                            // clusters).
                            Some((meshlets, list)) => {
                                for list in list.chunks(DRAW_CLUSTERS) {
                                    let draw = Draw {
                                        triangles: DrawTriangles::Clusters { meshlets, list },
                                        ..whole.clone()
                                    };
                                    self.draw(draw, meshlets.list_len(list));
                                }
                            }
                            None => {
                                let n = range.len();
                                let triangles = DrawTriangles::List(&bvh.primitive_indices()[range]);
                                self.draw(
                                    Draw {
                                        triangles,
                                        ..whole.clone()
                                    },
                                    n,
                                );
                            }
                        }
                    }
                }
                self.leaves = leaves;
            }
            NodeKind::Group(instances) => match hierarchy {
                Some(bvh) if !at.inside => cull_bvh(self, bvh, &at.frustum, |w, _, bn, inside| {
                    if inside || bn.is_leaf() {
                        for &i in &bvh.primitive_indices()[bn.range()] {
                            w.enter(at.child(i as usize), inside);
                        }
                        return false;
                    }
                    true
                }),
                _ => {
                    for i in 0..instances.len() {
                        self.enter(at.child(i), at.inside);
                    }
                }
            },
        }
    }
}

impl Renderer for FrustumCulling {
    fn name(&self) -> &'static str {
        "frustum"
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        let stats = self.culling.render(&mut self.raster, view, frame)?;
        crate::end_frame(&self.raster, stats)
    }

    fn memory_bytes(&self) -> usize {
        self.culling.memory_bytes() + self.raster.memory_bytes()
    }

    fn prepare(&mut self, width: u32, height: u32) -> Result<()> {
        crate::prepare_raster(&mut self.raster, self.culling.scene(), width, height);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_grid as grid;
    use crate::walk::MAX_FRAME_TRIANGLES;
    use occult_core::{Affine3A, Camera, Instance, SceneBuilder, Vec3};

    fn render(scene: &Arc<Scene>, params: &str, view: &View) -> Result<(FrameStats, Frame)> {
        let spec = if params.is_empty() {
            "frustum".to_string()
        } else {
            format!("frustum:{params}")
        };
        let mut r = crate::AlgoSpec::parse(&spec)?.build(scene.clone(), &RenderOptions::default())?;
        let mut f = Frame::new(view.width(), view.height())?;
        let stats = r.render(view, &mut f)?;
        Ok((stats, f))
    }

    /// 12 rows of 16 cubes seen from above (192 mesh occurrences in view, the faces of each
    /// behind its front hidden), on a ground of `ground` quads a side (one mesh, under them).
    fn cubes_from_above(ground: u32) -> (Arc<Scene>, View, Frame) {
        let mut b = SceneBuilder::new();
        let cube = b
            .add_mesh("cube", crate::tests::cube_mesh())
            .expect("a valid mesh adds");
        let ground = b.add_mesh("ground", grid(ground)).expect("a valid mesh adds");
        let mut instances = vec![Instance {
            // The unit grid in x, y laid on y = -0.5 over x in -14..14, z in -26..2.
            parent_from_child: Affine3A::from_scale_rotation_translation(
                Vec3::new(28.0, 28.0, 1.0),
                occult_core::glam::Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
                Vec3::new(-14.0, -0.5, 2.0),
            ),
            child: ground,
        }];
        instances.extend((0..192).map(|i| Instance {
            parent_from_child: Affine3A::from_translation(Vec3::new(
                (i % 16) as f32 * 1.5 - 12.0,
                0.0,
                -((i / 16) as f32) * 2.0,
            )),
            child: cube,
        }));
        let root = b.add_group("cubes", instances).expect("a group of known nodes adds");
        let scene = Arc::new(b.build(root).expect("the cubes build"));
        let (view, _) = crate::test_view(Vec3::new(0.3, 14.0, 8.0), Vec3::new(0.0, 0.0, -11.0), 96, 64);
        let frame = crate::tests::zbuffer_frame(&scene, &view);
        (scene, view, frame)
    }

    /// Beyond twice the sampled number of mesh occurrences (64 here, for a small scene), the
    /// hidden triangles are estimated from a sample of them: near the exact count (every
    /// occurrence descended), with a large occurrence among small ones too (descended whole,
    /// not stood for by the small ones' share), the same on one thread or three.
    #[test]
    fn many_mesh_occurrences_are_sampled_near_the_exact_count() {
        const SAMPLED: usize = 64;
        let raster = Rasterizer::new(occult_raster::RasterConfig::default()).expect("default rasterizer");
        let options = FrustumOptions {
            mesh_leaf_size: 2,
            ..FrustumOptions::default()
        };
        let mut pyramid = ZPyramid::new(96, 64).expect("small pyramid");
        // A ground of 2 triangles, then of 8,192 (more than the cubes' 2,304 together).
        for side in [1, 64] {
            let (scene, view, frame) = cubes_from_above(side);
            let h = Hierarchies::build(scene, &raster, &options).expect("frustum hierarchies build");
            let exact = h.hidden_triangles_sampling(&view, &frame, &mut pyramid, None, usize::MAX);
            let sampled = h.hidden_triangles_sampling(&view, &frame, &mut pyramid, None, SAMPLED);
            assert!(exact.met > 2 * SAMPLED, "{} occurrences met", exact.met);
            assert_eq!((exact.descended, sampled.met), (exact.met, exact.met));
            assert!(
                sampled.descended < sampled.met / 2,
                "{} of {} descended",
                sampled.descended,
                sampled.met
            );
            assert!(
                exact.hidden > h.triangles_in_view(&view) / 8,
                "the cubes' far faces are hidden"
            );
            let (e, x) = (sampled.hidden as f64, exact.hidden as f64);
            assert!(
                (0.95 * x..=1.25 * x).contains(&e),
                "ground {side}: estimate {e} against exact {x}"
            );
            let counts = crate::tests::on_threads(&[1, 3], |pool| {
                h.hidden_triangles_sampling(&view, &frame, &mut pyramid, Some(pool), SAMPLED)
                    .hidden
            });
            assert_eq!(counts, [sampled.hidden; 2], "one thread or three");
        }
    }

    /// The upper share of a sample: the ratio of its sums when every pair holds it, more
    /// when they spread, and less with the whole population sampled.
    #[test]
    fn the_upper_share_is_the_ratio_raised_by_the_spread() {
        let even = [(5.0, 10.0); 8];
        assert_eq!(upper_share(&even, 100, HIDDEN_LEAN), 0.5);
        let spread = [(0.0, 10.0), (10.0, 10.0), (2.0, 10.0), (8.0, 10.0)];
        let high = upper_share(&spread, 100, 1.0);
        assert!(high > 0.5 && high < 1.0, "{high}");
        assert!(
            upper_share(&spread, 100, 2.0) > high,
            "two standard errors raise it more"
        );
        assert_eq!(upper_share(&spread, 100, 0.0), 0.5, "no lean: the ratio");
        assert_eq!(upper_share(&spread, 4, 1.0), 0.5, "the whole population: the ratio");
        assert_eq!(
            upper_share(&[(1.0, 10.0)], 100, 1.0),
            1.0,
            "one pair says nothing of the spread"
        );
    }

    /// Batches of any size draw the frame and count what one batch does.
    #[test]
    fn batches_draw_what_one_batch_draws() {
        let mut b = SceneBuilder::new();
        let big = b.add_mesh("big", grid(40)).expect("a valid mesh adds");
        let small = b.add_mesh("small", grid(3)).expect("a valid mesh adds");
        let instances = (0..30)
            .map(|i| Instance {
                parent_from_child: Affine3A::from_translation(Vec3::new(
                    (i % 6) as f32 * 1.2,
                    (i / 6) as f32 * 1.2,
                    0.0,
                )),
                child: if i % 3 == 0 { big } else { small },
            })
            .collect();
        let root = b.add_group("grid", instances).expect("a group of known nodes adds");
        let scene = Arc::new(b.build(root).expect("the grid has triangles and builds"));
        // Close to the grid, so that the big meshes are cut by the frustum (index lists).
        let camera = Camera::look_at(Vec3::new(2.0, 2.5, 3.0), Vec3::new(3.0, 3.0, 0.0));
        let view = View::new(camera, 64, 48).expect("a 64x48 view of the grid");
        let (one, frame) = render(&scene, "leaf=16", &view).expect("frustum renders the grid");
        assert!(one.triangles_rasterized > 100, "the view shows the grid");
        for batch in [1, 2, 7] {
            let (s, f) =
                render(&scene, &format!("leaf=16,batch={batch}"), &view).expect("frustum renders the grid in batches");
            assert_eq!(f.items(), frame.items(), "batch={batch}");
            assert_eq!(
                (
                    s.triangles_submitted,
                    s.triangles_rasterized,
                    s.nodes_visited,
                    s.boxes_tested,
                    s.boxes_culled
                ),
                (
                    one.triangles_submitted,
                    one.triangles_rasterized,
                    one.nodes_visited,
                    one.boxes_tested,
                    one.boxes_culled
                ),
                "batch={batch}"
            );
        }
        assert!(render(&scene, "batch=0", &view).is_err());
    }

    /// A view of more triangles than a frame can draw is an error, found before drawing, for
    /// the renderers that walk everything in the view (the others cull what lies behind, or
    /// refuse the scene): never a failed allocation.
    #[test]
    fn too_many_triangles_in_view_is_an_error() {
        let mut b = SceneBuilder::new();
        // 20,000 triangles, under levels of 100, 10, 10 and 100 instances: 2·10^10 in view.
        let mut id = b.add_mesh("grid", grid(100)).expect("a valid mesh adds");
        for (level, count) in [100, 10, 10, 100].into_iter().enumerate() {
            let instances = (0..count)
                .map(|i| Instance {
                    parent_from_child: Affine3A::from_translation(Vec3::new(0.0, 0.0, -(i as f32) * 1e-3)),
                    child: id,
                })
                .collect();
            id = b
                .add_group(format!("level{level}"), instances)
                .expect("a group of a known node adds");
        }
        let scene = Arc::new(b.build(id).expect("2x10^10 instances build"));
        let view = View::new(
            Camera::look_at(Vec3::new(0.5, 0.5, 3.0), Vec3::new(0.5, 0.5, 0.0)),
            32,
            32,
        )
        .expect("a 32x32 view of the grid");
        let e = render(&scene, "", &view).unwrap_err();
        assert!(
            matches!(
                e,
                RenderError::TooManyInView {
                    renderer: "frustum",
                    limit: MAX_FRAME_TRIANGLES
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("more than 2000000000 triangle instances"), "{e}");
        // lzb walks the view in the same way, collecting leaves.
        let lzb = crate::AlgoSpec::parse("lzb")
            .expect("lzb is a known renderer")
            .build(scene.clone(), &RenderOptions::default())
            .expect("lzb builds for any scene")
            .render(&view, &mut Frame::new(32, 32).expect("a 32x32 frame"))
            .map(drop);
        assert!(
            matches!(lzb, Err(RenderError::TooManyInView { renderer: "lzb", .. })),
            "{lzb:?}"
        );
    }
}
