//! The randomized z-buffer: output-sensitive rendering from random surface samples.
//!
//! # References
//! Wand, Fischer, Peter, Meyer auf der Heide, Straßer, *The Randomized z-Buffer Algorithm:
//! Interactive Rendering of Highly Complex Scenes*, SIGGRAPH 2001
//! (`papers/randomized-z-buffer-wand-2001.txt`):
//! - §5.2 distribution lists and §5.3.1 octree with shortcuts and extended boxes, one global
//!   list per structure: [`occult_spatial::octree::sample`]; §7.1 area classes (one octree per
//!   class in the same list) and §7.3 instancing (one structure per DAG node, instances as
//!   entries with their transform, recursively): [`structure`];
//! - §5.3.2 box selection by depth accuracy ε, sample counts from area × maximum projection
//!   factor (§5.1, including the `1/cos α` distortion bounded per box) × `ln v` (§4.1.1),
//!   §7.1 large-triangle fallback (boxes whose triangles would get more than `large_threshold`
//!   samples each, i.e. a projected area above `threshold · d²/ln v` pixels, §8.3, are drawn by
//!   the rasterizer into the same frame): [`select`];
//! - §5.3.4 orientation classes (`orientation=N`): mesh triangles split by normal on a polar
//!   grid, each class's normal cone bounding the orientation factor of its boxes, boxes facing
//!   away skipped when back faces are rejected: [`structure`], [`select`];
//! - §5.2 area-proportional choice, uniform points on triangles, §5.3.3 back-face rejection,
//!   §4.1 per-pixel reconstruction and §4.2 splatting with side `d`: [`sample`]; §4.2
//!   Gaussian reconstruction (`recon=gauss`): [`recon`];
//! - §5.4 dynamic updates (`dynamic=on`): sampling from distribution trees
//!   ([`occult_spatial::DistributionTree`]), entries removed and inserted through
//!   [`Rzb::remove`] and [`Rzb::insert`];
//! - §7.2 sample caches per selected box, quantized to an object-space grid whose cells project
//!   to at most one splat, reused while the box's distance stays within a factor, LRU under a
//!   byte budget: [`cache`];
//! - §8.2 automatic ε by a minimum search over the measured selection + reconstruction time
//!   (`eps=auto`).
//!
//! The frame receives depth and item ids like every renderer: a sample of triangle `t` of a
//! mesh instance writes item `first_item + t`, with transforms composed from the root by the
//! crate's scene walk ([`crate::walk`]), so the fallback's triangles land bit-identical to `zbuffer`'s and
//! sampled pixels name real triangle instances. It is approximate (DESIGN invariant 3):
//! `compare` measures the share of pixels whose item differs from `zbuffer` and the PSNR.
//! Deterministic for a seed: each box's generator is seeded from the seed and the box alone,
//! and the per-thread buffers merge under the (depth, item) rule, so frames do not depend on
//! thread count; with caching a frame depends on the cache's history (which view built each
//! set), and with `eps=auto` on measured times.
//!
//! Cost: O(selected boxes + a · ln v / d² · log n) per frame, `a` the projected area in pixels
//! including hidden surfaces; O(n) memory over unique geometry.
//!
//! # Deviations
//! - Addition (`whole=on`, the default): a mesh instance more than half of whose triangles the
//!   §7.1 fallback draws is drawn whole, one draw, its sampled boxes dropped; so is one wholly
//!   beyond the near plane whose triangles would average more than twice the threshold of
//!   samples at its centre's distance, before any descent ([`select`]); `whole=off` is the
//!   paper's per-box fallback.
//! - Every group node gets its own structure (the paper merges singly referenced nodes into
//!   the parent's octree): composing transforms from the root, which bit-identical fallback
//!   draws need, requires the instance chain. One transform more per sample per level.
//! - Samples are drawn on the CPU in parallel into per-thread buffers merged under the frame's
//!   rule (the paper used OpenGL points).
//! - Each sample picks its position in a selected box's section by the list's binary search,
//!   then descends the instance chain without entering an instance: a Walker alias table per
//!   level ([`structure::AliasTable`], O(1)) instead of the list's binary search, a mesh's
//!   triangles read from a copy in list order, the point carried up the links taken: same
//!   distribution, fewer dependent loads on deep instancing.
//! - §5.3.2 selects boxes by their depth ratio; the paper's boxes are octree cubes, whose width
//!   across the view that ratio bounds as well. Ours are tight bounds (slabs, for rows of
//!   instances), so a selected box's view-space width is bounded too ([`select`]).
//! - Area scale of an instance is `|det|^(2/3)`, exact for the similarity transforms the
//!   generators use; for non-uniform scales the child's own-space distribution is used.
//! - Cached sets are built at the density needed at `z / tolerance`, so that they never fall
//!   below the required density while valid; back faces are not rejected from cached sets (as
//!   in the paper, so that validity depends on distance only). A set is built on a box's second
//!   request, not its first, and never for a split part ([`cache`]'s admission rule): over a
//!   walk that jumps, the paper's rule built sets that were never drawn again.
//! - §4.2 Gaussian reconstruction regenerates the samples in a second pass instead of keeping
//!   them (no memory per sample); it does not raise the sample count by itself (the paper uses
//!   about ten times the per-pixel count: `oversample=10`).
//! - §5.3.4 orientation classes exist for meshes only: a group's entries are instances, whose
//!   normals span their whole child (the paper has no instancing here); the cone bound is used
//!   only where the placement is a similarity (angles kept).
//! - §5.4 only the scene's own entries can be removed and inserted (item ids must name scene
//!   triangles; the scene is shared and immutable); an entry returns to its node of the static
//!   build. Sums are recomputed along the path in a fixed order instead of adjusted by the
//!   difference, so frames depend only on which entries are present. A change of a node's area
//!   is set on every instance of it, up the DAG (O(height) per referencing instance).
//!   `dynamic=on` samples by one tree descent per sample instead of the lists' binary searches
//!   and alias tables.
//! - Addition, `occlude=on` (the default; `off` is the paper's behaviour): the paper samples
//!   every surface in view, hidden or not. Here the selected boxes are sampled nearest first,
//!   in batches of growing size (the first about half a sample per pixel, then ×1.5); before
//!   each batch a z-pyramid is rebuilt over the frame (the large triangles, the batches
//!   before), and a box whose every sample would lose the depth test there gets none
//!   ([`occluded`], Greene's test with margins for the samples' own rounding, splats and the
//!   Gaussian pass's reach and tolerance). A box of at least `split` samples that is not
//!   hidden is split into its octree node's parts (a box of instances: into the instances,
//!   entered), each tested in turn (in parallel) and sampled at the density its own nearest
//!   distance asks, never above the box's ([`split`]). Counters `boxes_hidden`,
//!   `samples_hidden` (expected samples skipped), `boxes_split`. The error does not grow
//!   (tested against `occlude=off`).

pub mod cache;
mod occlude;
pub mod recon;
pub mod sample;
pub mod select;
pub mod structure;

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

use occult_core::{Aabb, Vec3};
use occult_core::{ItemId, Scene, View, NO_ITEM};
use occult_raster::{keep_fragment, Frame, PyramidCounts, Rasterizer, ZPyramid};
use occult_spatial::SampleOctreeConfig;
use rayon::prelude::*;

use crate::params::read_params;
use crate::{AlgorithmInfo, FrameStats, ParamDoc, Params, Phase, RenderError, RenderOptions, Renderer, Result};
use cache::{quantize, CachedSample, Plan, SampleCache};
use occlude::{occluded, occlusion_batches, split, PartTest, Reach};
use sample::{box_rng, piece_rng, sample_count, SampleCounts, Sampler, Target};
use select::Selection;
use structure::Structure;

/// Registry entry: `rzb:eps=1.5,d=2,cache=on,...`.
pub static INFO: AlgorithmInfo = AlgorithmInfo {
    name: "rzb",
    summary: "randomized z-buffer (Wand et al. 2001): random surface samples from an octree of distribution lists; approximate",
    params: &[
        ParamDoc { key: "seed", default: "1", help: "random seed (frames are a function of seed, scene, view and cache history)" },
        ParamDoc { key: "eps", default: "2", help: "depth accuracy (5.3.2): largest (z_max/z_min)^2 of a selected box, > 1, or auto (8.2 minimum search)" },
        ParamDoc { key: "d", default: "1", help: "splat side in pixels (4.2), 1..=16; 1 is per-pixel reconstruction (4.1)" },
        ParamDoc { key: "recon", default: "nearest", help: "reconstruction: nearest (each pixel keeps its nearest sample: per pixel for d=1 (4.1), splats for d>1 (4.2)) or gauss (4.2: splats delete hidden samples, color = Gaussian-weighted average of the visible samples)" },
        ParamDoc { key: "sigma", default: "0.5", help: "recon=gauss: standard deviation of the Gaussian in pixels, (0, 8]" },
        ParamDoc { key: "gauss_tolerance", default: "0.02", help: "recon=gauss: a sample is visible at a pixel when its view distance is within (1 + this) of the pixel's nearest, (0, 1]" },
        ParamDoc { key: "oversample", default: "1", help: "factor on the paper's sample count a*ln(v) (4.1.1), (0, 1000]" },
        ParamDoc { key: "large", default: "on", help: "draw boxes of large triangles with the z-buffer (7.1)" },
        ParamDoc { key: "whole", default: "on", help: "large=on: a mesh instance more than half of whose triangles the z-buffer draws (7.1), or whose triangles average more than twice threshold samples at its centre's distance, is drawn whole instead, its sampled boxes with it (not in the paper); off: per box only" },
        ParamDoc { key: "threshold", default: "1", help: "samples per triangle above which a box is z-buffered (7.1, 8.3: projected area d^2/ln v)" },
        ParamDoc { key: "area_ratio", default: "4", help: "largest area ratio within an area class (7.1), > 1" },
        ParamDoc { key: "orientation", default: "0", help: "orientation classes (5.3.4): bands of the polar grid of normal classes (2*bands^2 classes), 0..=8, 0 for none; bounds the orientation factor per box and skips boxes facing away when back faces are rejected" },
        ParamDoc { key: "leaf", default: "32", help: "entries per octree leaf (5.3.1), >= 1" },
        ParamDoc { key: "extension", default: "0.25", help: "extended boxes: growth per side as a fraction of the cell side (5.3.1), 0..=1" },
        ParamDoc { key: "cache", default: "off", help: "sample caching per selected box, quantized, LRU (7.2)" },
        ParamDoc { key: "cache_mib", default: "256", help: "sample cache budget in MiB (7.2)" },
        ParamDoc { key: "cache_tolerance", default: "1.25", help: "distance factor within which a cached set is reused (7.2), (1, 16]" },
        ParamDoc { key: "backface", default: "auto", help: "reject back-facing samples (5.3.3): auto follows the rasterizer's back-face culling, on, off" },
        ParamDoc { key: "dynamic", default: "off", help: "sample from distribution trees (5.4) so that entries can be removed and inserted through Rzb::remove/insert" },
        ParamDoc { key: "max_samples", default: "1e9", help: "most samples per frame; beyond, counts are scaled down (counter samples_capped)" },
        ParamDoc { key: "occlude", default: "on", help: "boxes sampled nearest first in batches; a box whose every sample would lose the depth test against what is drawn (large triangles, earlier batches, through a z-pyramid) gets none, and a large box that is not hidden is split into its octree parts, each tested and sampled at the density of its own nearest distance (not in the paper)" },
        ParamDoc { key: "split", default: "1024", help: "occlude=on: expected samples from which a box that is not hidden is split into its octree parts or entered instances, each tested in turn; 0 = never" },
    ],
    counters: &[
        "boxes_selected",
        "boxes_zbuffer",
        "instances_zbuffer",
        "boxes_backfacing",
        "instances_visited",
        "samples_generated",
        "samples_backfacing",
        "samples_capped",
        "samples_expected",
        "cache_hits",
        "cache_builds",
        "cache_evictions",
        "cache_kib",
        "eps_milli",
        "boxes_hidden",
        "samples_hidden",
        "boxes_split",
    ],
    conservative: false,
    bands: false,
    build: |scene, options, params| Ok(Box::new(Rzb::with_options(scene, options, &RzbOptions::from_params(params)?)?)),
};

/// Depth accuracy ε (§5.3.2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Epsilon {
    /// A fixed value > 1.
    Fixed(f64),
    /// §8.2: chosen per frame by a minimum search over measured time, starting at 2.
    Auto,
}

/// Reconstruction of the image from the samples (§4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Recon {
    /// Each pixel keeps its nearest sample: per-pixel reconstruction for `d = 1` (§4.1),
    /// splatting for `d > 1` (§4.2).
    Nearest,
    /// §4.2 Gaussian reconstruction: the `Nearest` pass deletes hidden samples and defines
    /// depth and items; colors are Gaussian-weighted averages of the visible samples
    /// ([`recon`]).
    Gauss,
}

/// Back-face rejection of samples (§5.3.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backface {
    /// As the rasterizer's `cull_backfaces`, so that `rzb` and `zbuffer` show the same faces.
    Auto,
    /// Reject samples on triangles facing away.
    On,
    /// Keep them.
    Off,
}

/// Tunables of [`Rzb`], with their units and what they trade.
#[derive(Clone, Debug, PartialEq)]
pub struct RzbOptions {
    /// Random seed: frames are a function of seed, scene, view (and cache history).
    pub seed: u64,
    /// Depth accuracy ε (> 1): largest `(z_max / z_min)²` of a selected box. Smaller selects
    /// more boxes and overestimates the projected area less (§8.2).
    pub eps: Epsilon,
    /// Splat side `d` in pixels (1 = per-pixel reconstruction), 1..=16.
    pub splat: u32,
    /// Reconstruction (§4.1, §4.2).
    pub recon: Recon,
    /// `Recon::Gauss`: standard deviation of the Gaussian in pixels, (0, 8].
    pub sigma: f32,
    /// `Recon::Gauss`: relative view-distance tolerance of the visibility test, (0, 1].
    pub gauss_tolerance: f32,
    /// Factor on the paper's sample count `a · ln v` (> 0): more fills more pixels, costs more.
    pub oversample: f64,
    /// §7.1: draw boxes of large triangles with the rasterizer.
    pub large: bool,
    /// Samples per triangle above which a box is drawn by the rasterizer (> 0).
    pub large_threshold: f64,
    /// With `large`: a mesh instance more than half of whose triangles §7.1 draws (or dense
    /// enough at its centre's distance) is drawn whole by the rasterizer, its sampled boxes with
    /// it (not in the paper; [`select`]).
    pub whole: bool,
    /// Largest area ratio within an area class (> 1; §8.3: 2..64 behave alike).
    pub area_ratio: f64,
    /// §5.3.4: bands of the polar grid of orientation classes (0 = none, ≤ 8).
    pub orientation: u32,
    /// Entries per octree leaf (≥ 1).
    pub leaf_size: usize,
    /// Extended boxes: growth per side as a fraction of the cell side (0..=1).
    pub extension: f32,
    /// §7.2 sample caching.
    pub cache: bool,
    /// Cache budget in MiB (≥ 1 when caching).
    pub cache_mib: usize,
    /// Distance factor within which a cached set is reused (> 1).
    pub cache_tolerance: f32,
    /// Back-face rejection.
    pub backface: Backface,
    /// §5.4: sample from distribution trees (summed areas in the octree nodes) instead of the
    /// static lists, so that entries can be removed and inserted ([`Rzb::remove`],
    /// [`Rzb::insert`]).
    pub dynamic: bool,
    /// Most samples per frame (≥ 1): beyond, every box's count is scaled down (counter
    /// `samples_capped`), so that a box at the near plane cannot stall a frame.
    pub max_samples: f64,
    /// Addition: skip the boxes hidden behind what is already drawn (see [`occluded`]),
    /// splitting large ones that are not ([`split`]).
    pub occlude: bool,
    /// `occlude`: a box that is not hidden, of at least this many expected samples, is split
    /// into parts tested in turn (0: never).
    pub split: f64,
}

impl Default for RzbOptions {
    fn default() -> Self {
        Self {
            seed: 1,
            eps: Epsilon::Fixed(2.0),
            splat: 1,
            recon: Recon::Nearest,
            sigma: 0.5,
            gauss_tolerance: 0.02,
            oversample: 1.0,
            large: true,
            large_threshold: 1.0,
            whole: true,
            area_ratio: 4.0,
            orientation: 0,
            leaf_size: 32,
            extension: 0.25,
            cache: false,
            cache_mib: 256,
            cache_tolerance: 1.25,
            backface: Backface::Auto,
            max_samples: 1e9,
            dynamic: false,
            occlude: true,
            split: 1024.0,
        }
    }
}

impl RzbOptions {
    /// The options set by `params` (keys of [`INFO`]), checked.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for a value that does not parse or is out of range.
    pub fn from_params(params: &Params) -> Result<Self> {
        let d = Self::default();
        let eps = match params.raw("eps") {
            Some("auto") => Epsilon::Auto,
            _ => Epsilon::Fixed(params.get("eps", 2.0f64)?),
        };
        let mut o = Self { eps, ..d };
        read_params!(params, o, { seed: "seed", splat: "d" });
        o.recon = match params.choice("recon", &["nearest", "gauss"], "nearest")? {
            "gauss" => Recon::Gauss,
            _ => Recon::Nearest,
        };
        read_params!(params, o, {
            sigma: "sigma",
            gauss_tolerance: "gauss_tolerance",
            oversample: "oversample",
            large: flag "large",
            whole: flag "whole",
            large_threshold: "threshold",
            area_ratio: "area_ratio",
            orientation: "orientation",
            leaf_size: "leaf",
            extension: "extension",
            cache: flag "cache",
            cache_mib: "cache_mib",
            cache_tolerance: "cache_tolerance",
        });
        o.backface = match params.choice("backface", &["auto", "on", "off"], "auto")? {
            "on" => Backface::On,
            "off" => Backface::Off,
            _ => Backface::Auto,
        };
        read_params!(params, o, { max_samples: "max_samples", dynamic: flag "dynamic", occlude: flag "occlude", split: "split" });
        o.validate()?;
        Ok(o)
    }

    /// Checks ranges.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] naming the parameter and value.
    pub fn validate(&self) -> Result<()> {
        let bad = |k: &str, v: String, want: &str| {
            Err(RenderError::BadParameter(format!(
                "rzb: {k}={v} is out of range ({want})"
            )))
        };
        if let Epsilon::Fixed(e) = self.eps {
            if !(e > 1.0 && e <= 1e6) {
                return bad("eps", e.to_string(), "a number in (1, 1e6] or auto");
            }
        }
        if !(1..=16).contains(&self.splat) {
            return bad("d", self.splat.to_string(), "1..=16");
        }
        if !(self.sigma > 0.0 && self.sigma <= 8.0) {
            return bad("sigma", self.sigma.to_string(), "(0, 8]");
        }
        if !(self.gauss_tolerance > 0.0 && self.gauss_tolerance <= 1.0) {
            return bad("gauss_tolerance", self.gauss_tolerance.to_string(), "(0, 1]");
        }
        if !(self.oversample > 0.0 && self.oversample <= 1e3) {
            return bad("oversample", self.oversample.to_string(), "(0, 1000]");
        }
        if !(self.large_threshold > 0.0 && self.large_threshold.is_finite()) {
            return bad("threshold", self.large_threshold.to_string(), "a positive number");
        }
        if !(self.area_ratio > 1.0 && self.area_ratio.is_finite()) {
            return bad("area_ratio", self.area_ratio.to_string(), "a number > 1");
        }
        if self.orientation > 8 {
            return bad("orientation", self.orientation.to_string(), "0..=8");
        }
        if !(1..=1 << 20).contains(&self.leaf_size) {
            return bad("leaf", self.leaf_size.to_string(), "1..=1048576");
        }
        if !(0.0..=1.0).contains(&self.extension) {
            return bad("extension", self.extension.to_string(), "0..=1");
        }
        if !(1..=1 << 20).contains(&self.cache_mib) {
            return bad("cache_mib", self.cache_mib.to_string(), "1..=1048576");
        }
        if !(self.cache_tolerance > 1.0 && self.cache_tolerance <= 16.0) {
            return bad("cache_tolerance", self.cache_tolerance.to_string(), "(1, 16]");
        }
        if !(self.split >= 0.0 && self.split.is_finite()) {
            return bad("split", self.split.to_string(), "a number >= 0");
        }
        if !(self.max_samples >= 1.0 && self.max_samples <= 1e12) {
            return bad("max_samples", self.max_samples.to_string(), "1..=1e12");
        }
        Ok(())
    }
}

/// §8.2: pattern search on ε over frames: even frames measure the current ε, odd frames a
/// neighbour `ε·step^±1`; the better one is kept, a failed direction reverses and halves the
/// step (in log ε).
#[derive(Clone, Debug)]
struct AutoEps {
    eps: f64,
    log_step: f64,
    dir: f64,
    base_time: Option<f64>,
}

impl AutoEps {
    const MIN: f64 = 1.02;
    const MAX: f64 = 64.0;

    fn new() -> Self {
        Self {
            eps: 2.0,
            log_step: 0.5,
            dir: -1.0,
            base_time: None,
        }
    }

    fn trial(&self) -> f64 {
        (self.eps * (self.dir * self.log_step).exp()).clamp(Self::MIN, Self::MAX)
    }

    /// The ε for the next frame.
    fn next(&self) -> f64 {
        if self.base_time.is_some() {
            self.trial()
        } else {
            self.eps
        }
    }

    /// Records the time of the frame rendered with [`AutoEps::next`].
    fn record(&mut self, seconds: f64) {
        match self.base_time.take() {
            None => self.base_time = Some(seconds),
            Some(base) => {
                if seconds < base {
                    self.eps = self.trial();
                } else {
                    self.dir = -self.dir;
                    self.log_step = (self.log_step * 0.5).max(0.02);
                }
            }
        }
    }
}

/// The randomized z-buffer renderer.
pub struct Rzb {
    scene: Arc<Scene>,
    raster: Rasterizer,
    opts: RzbOptions,
    structures: Vec<Structure>,
    cache: Option<SampleCache>,
    auto: Option<AutoEps>,
    frame_index: u64,
    scratch: Vec<(Vec<f32>, Vec<ItemId>)>,
    /// `occlude=on`: the depth pyramid of the frame being sampled.
    pyramid: Option<ZPyramid>,
    /// §5.4: for each DAG node, the (group, instance index, area scale) of the instances
    /// that reference it.
    referrers: Vec<Vec<(u32, u32, f64)>>,
}

impl Rzb {
    /// What the renderer learns from a whole frame besides its cache: the frame count and
    /// §8.2's search for ε (tests: a cancelled frame leaves them as they were).
    #[cfg(test)]
    pub(crate) fn learnt_state(&self) -> String {
        format!("{} {:?}", self.frame_index, self.auto)
    }

    /// Builds the sampling structures of `scene` (§5.3.1, §7.1, §7.3).
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for options out of range; raster configuration errors.
    pub fn with_options(scene: Arc<Scene>, options: &RenderOptions, opts: &RzbOptions) -> Result<Self> {
        opts.validate()?;
        let raster = Rasterizer::new(options.raster.clone())?;
        let config = SampleOctreeConfig {
            leaf_size: opts.leaf_size,
            extension: opts.extension,
            ..SampleOctreeConfig::default()
        };
        let structures = raster
            .install(|| structure::build_all(&scene, &config, opts.area_ratio, opts.orientation, opts.dynamic))
            .map_err(|e| RenderError::BadParameter(format!("rzb: {e}")))?;
        let referrers = if opts.dynamic {
            let mut r = vec![Vec::new(); scene.nodes().len()];
            for (g, n) in scene.nodes().iter().enumerate() {
                if let occult_core::NodeKind::Group(insts) = n.kind() {
                    for (e, inst) in insts.iter().enumerate() {
                        r[inst.child.index()].push((
                            g as u32,
                            e as u32,
                            structure::area_scale(&inst.parent_from_child),
                        ));
                    }
                }
            }
            r
        } else {
            Vec::new()
        };
        let mut rzb = Self {
            scene,
            raster,
            cache: opts
                .cache
                .then(|| SampleCache::new(opts.cache_mib << 20, opts.cache_tolerance)),
            auto: (opts.eps == Epsilon::Auto).then(AutoEps::new),
            opts: opts.clone(),
            structures,
            frame_index: 0,
            scratch: Vec::new(),
            pyramid: None,
            referrers,
        };
        if opts.dynamic {
            rzb.settle();
        }
        Ok(rzb)
    }

    /// §5.4: sets every instance entry's area and item count from its child's tree (children
    /// come before parents in the DAG's order), so that the values an update propagates are
    /// the ones the trees start with, bit for bit.
    fn settle(&mut self) {
        for n in 0..self.structures.len() {
            if let occult_core::NodeKind::Group(insts) = self.scene.node(occult_core::NodeId(n as u32)).kind() {
                for (e, inst) in insts.iter().enumerate() {
                    let child = &self.structures[inst.child.index()];
                    let (area, items) = child
                        .tree
                        .as_ref()
                        .map_or((0.0, 0), |t| (t.total_area(), t.total_weight()));
                    let scaled = area * structure::area_scale(&inst.parent_from_child);
                    if let Some(t) = self.structures[n].tree.as_mut() {
                        // The area is finite and non-negative (sums of such).
                        let _ = t.set_entry(e as u32, scaled, items);
                    }
                }
            }
            if let Some(t) = self.structures[n].tree.as_ref() {
                self.structures[n].area = t.total_area();
            }
        }
    }

    /// §5.4: removes entry `entry` of DAG node `node` (a triangle of a mesh, an instance of a
    /// group) from sampling and from the large-triangle fallback: O(height) in the node's tree,
    /// then the node's new area and item count are set on every instance of it (O(height) per
    /// referencing instance, up the DAG). Sample caches are emptied (their sets may hold it).
    ///
    /// Only the scene's own entries can be removed and inserted: item ids name scene
    /// triangles, and the scene is shared and immutable.
    ///
    /// # Errors
    /// [`RenderError::Update`] without `dynamic=on`, for a node or entry that does not exist,
    /// is not present, or has no area.
    pub fn remove(&mut self, node: occult_core::NodeId, entry: u32) -> Result<()> {
        self.update(node, entry, false)
    }

    /// §5.4: inserts entry `entry` of DAG node `node` again (at its node of the static build),
    /// the inverse of [`Rzb::remove`]: with the same seed, frames after an insertion and a
    /// removal of the same entry are those before (the trees' sums are recomputed in a fixed
    /// order, not adjusted).
    ///
    /// # Errors
    /// As [`Rzb::remove`]; an entry already present is an error.
    pub fn insert(&mut self, node: occult_core::NodeId, entry: u32) -> Result<()> {
        self.update(node, entry, true)
    }

    /// True when entry `entry` of node `node` is sampled (always, without `dynamic=on`, for an
    /// entry with area).
    pub fn contains(&self, node: occult_core::NodeId, entry: u32) -> bool {
        let Some(st) = self.structures.get(node.index()) else {
            return false;
        };
        match &st.tree {
            Some(t) => t.contains(entry),
            None => st.octree.entries().contains(&entry),
        }
    }

    fn update(&mut self, node: occult_core::NodeId, entry: u32, insert: bool) -> Result<()> {
        let err = |m: String| Err(RenderError::Update(format!("rzb: {m}")));
        if !self.opts.dynamic {
            return err("dynamic updates need dynamic=on".into());
        }
        let Some(st) = self.structures.get_mut(node.index()) else {
            return err(format!("no node {}", node.0));
        };
        let Some(tree) = st.tree.as_mut() else {
            return err(format!("node {} has no distribution tree", node.0));
        };
        let result = if insert {
            match tree.home(entry) {
                Some(home) => {
                    let (area, weight) = tree.entry(entry);
                    tree.insert_at(entry, home, area, weight)
                }
                None => Err(format!(
                    "entry {entry} of node {} does not exist or has no area",
                    node.0
                )),
            }
        } else {
            tree.remove(entry).map_err(|m| format!("node {}: {m}", node.0))
        };
        if let Err(m) = result {
            return err(m);
        }
        self.propagate(node.index());
        if let Some(c) = self.cache.as_mut() {
            *c = SampleCache::new(c.budget(), self.opts.cache_tolerance);
        }
        Ok(())
    }

    /// Sets node `n`'s area and item count from its tree and passes them to every instance of
    /// it, recursively up the DAG.
    fn propagate(&mut self, n: usize) {
        let Some(tree) = self.structures[n].tree.as_ref() else {
            return;
        };
        let (area, items) = (tree.total_area(), tree.total_weight());
        self.structures[n].area = area;
        let mut groups: Vec<u32> = Vec::new();
        for k in 0..self.referrers[n].len() {
            let (g, e, scale) = self.referrers[n][k];
            if let Some(t) = self.structures[g as usize].tree.as_mut() {
                // The area is finite and non-negative (sums of such).
                let _ = t.set_entry(e, area * scale, items);
            }
            if !groups.contains(&g) {
                groups.push(g);
            }
        }
        // Each group once, after all its entries changed.
        for g in groups {
            self.propagate(g as usize);
        }
    }

    /// The options.
    pub fn options(&self) -> &RzbOptions {
        &self.opts
    }

    /// Bytes held by the sample caches (never above the budget).
    pub fn cache_bytes(&self) -> usize {
        self.cache.as_ref().map_or(0, SampleCache::bytes)
    }
}

/// Samples per work unit.
const PIECE: u64 = 1 << 14;

/// A run of samples of one box drawn by one thread.
struct Unit {
    job: usize,
    piece: u64,
    first: usize,
    len: usize,
}

/// Work units a drawing thread takes at a time from its batch.
const UNITS_TAKEN: usize = 8;

/// Where a selected box's samples come from this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Source {
    /// Generated now, not cached.
    Direct,
    /// A valid cached set.
    Hit,
    /// A set built now (index into the built sets).
    Built(usize),
}

impl Renderer for Rzb {
    fn name(&self) -> &'static str {
        "rzb"
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        let (start, _, mut stats) = crate::begin_frame(&mut self.raster, view, frame)?;
        // This frame's number; the renderer counts it only once the frame is whole (a
        // cancelled frame leaves the renderer as it was, as the cache and ε below).
        let frame_index = self.frame_index + 1;
        let eps = match (&self.auto, self.opts.eps) {
            (Some(a), _) => a.next(),
            (None, Epsilon::Fixed(e)) => e,
            (None, Epsilon::Auto) => 2.0,
        };

        // §5.3.2 / §7.1 / §7.3: box selection.
        let t_select = Instant::now();
        let backface = match self.opts.backface {
            Backface::Auto => self.raster.config().cull_backfaces,
            Backface::On => true,
            Backface::Off => false,
        };
        let mut sel = Selection::run(&self.scene, &self.structures, view, &self.opts, eps, backface);
        let select_time = t_select.elapsed();
        stats.phases.add(Phase::Cull, select_time);
        stats.boxes_tested = sel.boxes_tested;
        stats.boxes_culled = sel.boxes_culled;
        stats.nodes_visited = sel.boxes_tested;
        crate::rasterize(&mut self.raster, view, frame, &sel.draws, &mut stats);
        // §4.2 Gaussian reconstruction keeps the fallback's pixels exact: remember them.
        let gauss = self.opts.recon == Recon::Gauss;
        let raster_items: Vec<ItemId> = if gauss { frame.items().to_vec() } else { Vec::new() };

        // §4 / §5.2 / §7.2: samples.
        let t_samples = Instant::now();
        let mut jobs = std::mem::take(&mut sel.jobs);
        let selected = jobs.len();
        let expected: f64 = jobs.iter().map(|j| j.samples).sum();
        let cap = if expected > self.opts.max_samples {
            self.opts.max_samples / expected
        } else {
            1.0
        };
        let sampler = Sampler {
            scene: &self.scene,
            structures: &self.structures,
            splat: self.opts.splat,
            backface,
            eye: view.camera().eye,
            far_depth: view.far_depth(),
            seed: self.opts.seed,
            width: view.width(),
            height: view.height(),
        };
        let consts = select::ViewConsts::new(view, self.opts.splat);
        let tol = self.opts.cache_tolerance;
        let (width, height) = (frame.width(), frame.height());
        let pixels = width as usize * height as usize;
        // Addition (`occlude=on`): the boxes nearest first, in batches; a box every sample of
        // which would lose the depth test against the frame as drawn so far (the large
        // triangles, the batches before) gets none ([`occluded`]).
        let order: Vec<usize> = if self.opts.occlude {
            let mut o: Vec<usize> = (0..jobs.len()).collect();
            o.sort_by(|&a, &b| jobs[a].z_min.total_cmp(&jobs[b].z_min).then(a.cmp(&b)));
            o
        } else {
            (0..jobs.len()).collect()
        };
        let batches = if self.opts.occlude {
            occlusion_batches(&order, |k| jobs[k].samples * cap, pixels as f64)
        } else {
            std::iter::once(0..order.len()).collect()
        };
        let mut pyramid = if self.opts.occlude {
            let fits = |p: &ZPyramid| p.width() == width && p.height() == height;
            if !self.pyramid.as_ref().is_some_and(fits) {
                self.pyramid = Some(ZPyramid::new(width, height)?);
            }
            self.pyramid.take()
        } else {
            None
        };
        let reach = Reach::of(&self.opts);
        let mut hidden = (0u64, 0f64);
        let mut split_count = 0u64;
        let mut pyramid_counts = PyramidCounts::default();
        let mut hits = 0u64;
        let mut sources: Vec<Option<Source>> = vec![None; jobs.len()];
        let mut to_build: Vec<usize> = Vec::new();
        // §7.2: the sets drawn and the boxes sampled fresh this frame, told to the cache once
        // the frame is whole (a cancelled frame leaves the cache as it was).
        let (mut touched, mut noted): (Vec<cache::BoxKey>, Vec<(cache::BoxKey, f32)>) = (Vec::new(), Vec::new());
        let mut built: Vec<(Vec<CachedSample>, u64)> = Vec::new();
        let mut units: Vec<Unit> = Vec::new();
        let mut counts: Vec<SampleCounts> = Vec::new();
        let batch_count = batches.len();
        // Progress: samples drawn of those expected (cap included), counted per work unit, where
        // the cancellation is checked too.
        let control = self.raster.config().control.clone();
        let samples_drawn = AtomicU64::new(0);
        let samples_total = (expected * cap).min(u64::MAX as f64) as u64;
        let raster: &Rasterizer = &self.raster;
        let unit_done = |len: usize| {
            let done = samples_drawn.fetch_add(len as u64, Ordering::Relaxed) + len as u64;
            crate::report_part(raster, done, samples_total);
        };
        for (batch_index, batch) in batches.into_iter().enumerate() {
            crate::check_cancel(&self.raster)?;
            if let Some(p) = pyramid.as_mut() {
                let t = Instant::now();
                p.rebuild(frame);
                stats.phases.add(Phase::DepthStructure, t.elapsed());
            }
            let (first_build, first_unit) = (to_build.len(), units.len());
            // The batch's boxes in turn; the parts of those split are tested (and split again)
            // afterwards, in parallel.
            let mut accepted: Vec<usize> = Vec::with_capacity(batch.len());
            let mut to_resolve: Vec<select::Job> = Vec::new();
            for &k in &order[batch] {
                let job = &jobs[k];
                // §7.2: a valid set, one to build (the box was selected in the frame before at
                // a similar distance), or fresh samples ([`cache`]'s admission rule).
                // The parts of a split box (`occlude=on`) are sampled fresh: a part is an
                // instance or an octree node with a few samples, whose set would cost more to
                // look up and keep than to draw; the box itself is remembered and cached whole.
                let key = job.key();
                let plan = match &self.cache {
                    Some(c) => match c.plan(&key, job.z_min, frame_index) {
                        Plan::Build if !c.fits(job.samples * cap * (tol * tol) as f64) => Plan::Direct,
                        p => p,
                    },
                    None => Plan::Direct,
                };
                if let Some(p) = &pyramid {
                    // Cached sets are quantized to cells of at most a splat at the box's
                    // distance, which may move a sample that far out of the box.
                    let bounds = match plan {
                        Plan::Hit | Plan::Build => {
                            let cell = (consts.splat as f64 * job.z_min as f64 / consts.focal_px) as f32
                                / job.scale.max(f32::MIN_POSITIVE);
                            Aabb::new(job.bounds.min - Vec3::splat(cell), job.bounds.max + Vec3::splat(cell))
                        }
                        Plan::Direct => job.bounds,
                    };
                    if occluded(p, frame, &job.clip_from_structure, &bounds, reach, &mut pyramid_counts) {
                        hidden.0 += 1;
                        hidden.1 += job.samples * cap;
                        continue;
                    }
                    // A box drawn from a cached set is not split: its set is drawn whole.
                    let parts = match plan {
                        Plan::Direct => split(&self.scene, view, &self.structures, job, self.opts.split),
                        Plan::Hit | Plan::Build => None,
                    };
                    if let Some(parts) = parts {
                        if self.cache.is_some() {
                            noted.push((key, job.z_min));
                        }
                        split_count += 1;
                        to_resolve.extend(parts);
                        continue;
                    }
                }
                let job = &jobs[k];
                accepted.push(k);
                let src = match plan {
                    Plan::Hit => {
                        touched.push(key);
                        hits += 1;
                        Source::Hit
                    }
                    Plan::Build => {
                        to_build.push(k);
                        Source::Built(to_build.len() - 1)
                    }
                    Plan::Direct => {
                        if self.cache.is_some() {
                            noted.push((key, job.z_min));
                        }
                        Source::Direct
                    }
                };
                sources[k] = Some(src);
            }
            if let Some(p) = &pyramid {
                let test = PartTest {
                    scene: &self.scene,
                    view,
                    structures: &self.structures,
                    pyramid: p,
                    frame,
                    reach,
                    min_samples: self.opts.split,
                    cap,
                };
                for parts in self.raster.install(|| test.resolve_all(to_resolve)) {
                    hidden.0 += parts.hidden;
                    hidden.1 += parts.hidden_samples;
                    split_count += parts.splits;
                    for part in parts.accepted {
                        jobs.push(part);
                        sources.push(Some(Source::Direct));
                        accepted.push(jobs.len() - 1);
                    }
                }
            }
            // §7.2: build the missing sets (parallel over boxes), at the density needed at
            // z_min / tolerance, quantized to cells that project to at most one splat there.
            let new_sets: Vec<(Vec<CachedSample>, u64)> = self.raster.install(|| {
                to_build[first_build..]
                    .par_iter()
                    .map(|&k| {
                        if control.is_cancelled() {
                            return (Vec::new(), 0); // never stored: the frame returns first
                        }
                        let job = &jobs[k];
                        let mut rng = box_rng(sampler.seed, job);
                        let n = sample_count(job.samples * cap * (tol * tol) as f64, &mut rng);
                        let z = job.z_min / tol;
                        let cell = (consts.splat as f64 * z as f64 / consts.focal_px) as f32
                            / job.scale.max(f32::MIN_POSITIVE);
                        let place = sample::Place::new(job, sampler.eye, false);
                        let mut points = Vec::with_capacity(n.min(1 << 24) as usize);
                        sampler.generate(
                            job.structure,
                            job.range.clone(),
                            sample::Part::of(job),
                            n,
                            &place,
                            &mut rng,
                            &mut |pl, p, _, item| {
                                points.push((pl.job_from_space.transform_point3(p), item - job.base));
                            },
                        );
                        (quantize(&points, cell.max(f32::MIN_POSITIVE)), n)
                    })
                    .collect()
            });
            crate::check_cancel(&self.raster)?;
            built.extend(new_sets);
            // Work units of at most PIECE samples: a direct box's pieces each have their own
            // generator (seeded from the box and the piece index), so the frame does not depend
            // on how units are spread over threads.
            for &k in &accepted {
                let (job, Some(src)) = (&jobs[k], &sources[k]) else {
                    continue;
                };
                let n = match src {
                    Source::Direct => {
                        let mut rng = box_rng(sampler.seed, job);
                        sample_count(job.samples * cap, &mut rng)
                    }
                    Source::Hit => self.cache.as_ref().map_or(0, |c| c.samples(&job.key()).len() as u64),
                    Source::Built(b) => built[*b].0.len() as u64,
                };
                let mut first = 0u64;
                let mut piece = 0u64;
                while first < n {
                    let len = (n - first).min(PIECE);
                    units.push(Unit {
                        job: k,
                        piece,
                        first: first as usize,
                        len: len as usize,
                    });
                    first += len;
                    piece += 1;
                }
            }
            // One target per thread, each taking the batch's units a few at a time in turn (their
            // samples vary from one to thousands, so fixed runs left a thread idle); target 0 is
            // the frame, the others scratch buffers merged afterwards under the (depth, item)
            // rule, which does not depend on which target drew a sample.
            let batch_units = &units[first_unit..];
            let max_threads = (1usize << 30) / (pixels * 12).max(1);
            let chunk_count = self
                .raster
                .thread_count()
                .clamp(1, max_threads.max(1))
                .min(batch_units.len().max(1));
            let next_unit = AtomicUsize::new(first_unit);
            if batch_units.is_empty() && batch_index + 1 < batch_count {
                // Nothing to draw (every part hidden, say): the parts go as after a draw.
                if !gauss {
                    jobs.truncate(selected);
                    sources.truncate(selected);
                    units.clear();
                }
                continue;
            }
            self.scratch.truncate(chunk_count.saturating_sub(1));
            while self.scratch.len() + 1 < chunk_count {
                self.scratch.push((Vec::new(), Vec::new()));
            }
            let cache = self.cache.as_ref();
            let (frame_depth, frame_items) = frame.buffers_mut();
            let mut targets: Vec<Target<'_>> = Vec::with_capacity(chunk_count);
            targets.push(Target {
                depth: frame_depth,
                items: frame_items,
                width,
                height,
            });
            for (d, i) in self.scratch.iter_mut() {
                d.clear();
                d.resize(pixels, 0.0);
                i.clear();
                i.resize(pixels, NO_ITEM);
                targets.push(Target {
                    depth: d,
                    items: i,
                    width,
                    height,
                });
            }
            let batch_counts: Vec<SampleCounts> = {
                let (units, sources, built, next_unit) = (&units, &sources, &built, &next_unit);
                self.raster.install(|| {
                    targets
                        .par_iter_mut()
                        .map(|target| {
                            let mut counts = SampleCounts::default();
                            let mut unreported = 0;
                            loop {
                                let first = next_unit.fetch_add(UNITS_TAKEN, Ordering::Relaxed);
                                if first >= units.len() || control.is_cancelled() {
                                    break;
                                }
                                for u in &units[first..(first + UNITS_TAKEN).min(units.len())] {
                                    let job = &jobs[u.job];
                                    let set = match sources[u.job] {
                                        Some(Source::Direct) => {
                                            let mut rng = piece_rng(sampler.seed, job, u.piece);
                                            sampler.draw_job(job, u.len as u64, &mut rng, target, &mut counts);
                                            None
                                        }
                                        Some(Source::Hit) => {
                                            cache.map(|c| &c.samples(&job.key())[u.first..u.first + u.len])
                                        }
                                        Some(Source::Built(b)) => Some(&built[b].0[u.first..u.first + u.len]),
                                        None => None,
                                    };
                                    if let Some(set) = set {
                                        sampler.draw_cached(
                                            &job.clip_from_structure,
                                            job.base,
                                            set,
                                            target,
                                            &mut counts,
                                        );
                                    }
                                    unreported += u.len;
                                }
                                // Progress told every few thousand samples, not per unit: the
                                // shared counters are one cache line for every thread.
                                if unreported >= PIECE as usize {
                                    unit_done(std::mem::take(&mut unreported));
                                }
                            }
                            unit_done(unreported);
                            counts
                        })
                        .collect()
                })
            };
            counts.extend(batch_counts);
            // Merge the scratch buffers into the frame.
            let (frame_depth, frame_items) = frame.buffers_mut();
            for (d, i) in self.scratch.iter().take(chunk_count.saturating_sub(1)) {
                for p in 0..pixels {
                    if d[p] > 0.0 {
                        keep_fragment(&mut frame_depth[p], &mut frame_items[p], d[p], i[p]);
                    }
                }
            }
            // The batch's parts are drawn: the next batch's take their places (only the
            // Gaussian pass goes over every unit again). A frame of the 1.4·10^14 forest splits
            // its boxes into 8.8 M parts of 208 bytes; kept to the frame's end, they made
            // 2.3 GB of fresh pages, a quarter of the frame in page faults.
            if !gauss {
                jobs.truncate(selected);
                sources.truncate(selected);
                units.clear();
            }
        }
        if pyramid.is_some() {
            self.pyramid = pyramid;
        }
        // §4.2: the Gaussian pass over the same samples.
        if gauss {
            let filter = recon::Gaussian {
                depth: frame.depth(),
                width,
                height,
                sigma: self.opts.sigma,
                keep: 1.0 / (1.0 + self.opts.gauss_tolerance),
            };
            let light = occult_raster::light_direction(view);
            let scene = &*self.scene;
            let cache = self.cache.as_ref();
            // One accumulation buffer per contiguous run of units, one run per thread, bounded
            // by the same budget as the scratch buffers (sums of integers: any split gives the
            // same image).
            let max_runs = ((1usize << 30) / (pixels * recon::ACCUM_BYTES).max(1)).max(1);
            let run_count = self.raster.thread_count().clamp(1, max_runs).min(units.len().max(1));
            let runs: Vec<std::ops::Range<usize>> = (0..run_count)
                .map(|t| t * units.len() / run_count..(t + 1) * units.len() / run_count)
                .collect();
            let sums: Vec<Vec<recon::Accum>> = self.raster.install(|| {
                runs.par_iter()
                    .map(|run| {
                        let mut acc = vec![[0u64; 4]; pixels];
                        let mut colors = recon::Colors::new(scene, light);
                        let mut counts = SampleCounts::default();
                        let mut emit = |s: sample::Projected| {
                            let c = colors.get(s.item);
                            filter.add(s, c, &mut acc);
                        };
                        for u in &units[run.clone()] {
                            let job = &jobs[u.job];
                            let set = match sources[u.job] {
                                Some(Source::Direct) => {
                                    let mut rng = piece_rng(sampler.seed, job, u.piece);
                                    sampler.project_job(job, u.len as u64, &mut rng, &mut counts, &mut emit);
                                    None
                                }
                                Some(Source::Hit) => cache.map(|c| &c.samples(&job.key())[u.first..u.first + u.len]),
                                Some(Source::Built(b)) => Some(&built[b].0[u.first..u.first + u.len]),
                                None => None,
                            };
                            if let Some(set) = set {
                                sampler.project_cached(&job.clip_from_structure, job.base, set, &mut counts, &mut emit);
                            }
                        }
                        acc
                    })
                    .collect()
            });
            let mut colors = recon::Colors::new(scene, light);
            let resolved: Vec<[u8; 4]> = (0..pixels)
                .map(|p| {
                    let mut sum = [0u64; 4];
                    for s in &sums {
                        for k in 0..4 {
                            sum[k] += s[p][k];
                        }
                    }
                    recon::resolve(&sum, frame.items()[p], raster_items[p], &mut colors)
                })
                .collect();
            frame.resolved_color_mut().copy_from_slice(&resolved);
        }
        let built_samples: u64 = built.iter().map(|(_, generated)| generated).sum();
        let samples_time = t_samples.elapsed();
        stats.phases.add(Phase::Samples, samples_time);
        let sum = counts.iter().fold(SampleCounts::default(), |a, c| SampleCounts {
            generated: a.generated + c.generated,
            backfacing: a.backfacing + c.backfacing,
            drawn: a.drawn + c.drawn,
        });
        stats.samples_drawn = sum.drawn;
        let c = &mut stats.counters;
        c.add("boxes_selected", selected as u64);
        c.add("boxes_zbuffer", sel.boxes_zbuffer);
        c.add("instances_zbuffer", sel.instances_zbuffer);
        if self.opts.orientation > 0 {
            c.add("boxes_backfacing", sel.boxes_backfacing);
        }
        c.add("instances_visited", sel.instances_visited);
        c.add("samples_generated", sum.generated + built_samples);
        c.add("samples_backfacing", sum.backfacing);
        c.add("samples_capped", (cap < 1.0) as u64);
        c.add("samples_expected", expected.min(u64::MAX as f64) as u64);
        c.add("eps_milli", (eps * 1000.0).round() as u64);
        if self.opts.occlude {
            c.add("boxes_hidden", hidden.0);
            c.add("samples_hidden", hidden.1.min(u64::MAX as f64) as u64);
            c.add("boxes_split", split_count);
        }
        stats.total = start.elapsed();
        // A cancelled frame leaves the renderer as it was: the cache (its sets may be
        // incomplete), §8.2's search for ε and the frame count learn of the frame only after
        // its last check.
        let mut stats = crate::end_frame(&self.raster, stats)?;
        self.frame_index = frame_index;
        if let Some(a) = self.auto.as_mut() {
            a.record((select_time + samples_time).as_secs_f64());
        }
        if let Some(c) = self.cache.as_mut() {
            let t_store = Instant::now();
            for key in &touched {
                c.touch(key, frame_index);
            }
            for (key, z_min) in &noted {
                c.note(key, *z_min);
            }
            let mut evictions = 0u64;
            for (b, (set, _)) in built.into_iter().enumerate() {
                let job = &jobs[to_build[b]];
                evictions += c.insert(job.key(), set, job.z_min, frame_index);
            }
            c.end_frame(frame_index);
            let store_time = t_store.elapsed();
            stats.phases.add(Phase::Samples, store_time);
            stats.total += store_time;
            let counters = &mut stats.counters;
            counters.add("cache_hits", hits);
            counters.add("cache_builds", to_build.len() as u64);
            counters.add("cache_evictions", evictions);
            counters.add("cache_kib", (c.bytes() >> 10) as u64);
        }
        Ok(stats)
    }

    /// The rasterizer's private frames (the §7.1 fallback) and the pyramid of `occlude=on`.
    fn prepare(&mut self, width: u32, height: u32) -> Result<()> {
        crate::prepare_raster(&mut self.raster, &self.scene, width, height);
        if self.opts.occlude {
            crate::sized_pyramid(&mut self.pyramid, width, height)?;
        }
        Ok(())
    }

    fn memory_bytes(&self) -> usize {
        self.structures.iter().map(Structure::memory_bytes).sum::<usize>()
            + self.cache.as_ref().map_or(0, |c| c.bytes() + c.seen_bytes())
            + self
                .scratch
                .iter()
                .map(|(d, i)| d.len() * 4 + i.len() * 8)
                .sum::<usize>()
            + self.raster.memory_bytes()
    }

    fn is_conservative(&self) -> bool {
        false
    }
}
