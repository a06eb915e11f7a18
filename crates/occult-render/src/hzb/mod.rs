//! Hierarchical z-buffer obscuration culling with temporal coherence.
//!
//! # References
//! - C. Georges, *Obscuration Culling on Parallel Graphics Architectures*, UNC TR95-017 (1995)
//!   (`papers/obscuration-culling-georges-1995.txt`), after N. Greene, M. Kass, G. Miller,
//!   *Hierarchical Z-Buffer Visibility* (SIGGRAPH 1993).
//!
//! # What it does, part by part
//! - **Octree with hybrid redistribution (§3.1)**, [`occult_spatial::HybridOctree`]: one per
//!   node of the scene DAG that needs one: every group (its primitives are its instances, each
//!   a box placed by the instance transform) and every mesh of more than `leaf` triangles (its
//!   primitives are triangles). An instance whose prototype has an octree is a primitive with a
//!   transform: reaching it continues in the prototype's octree; an instance of a small mesh is
//!   drawn whole. Shared primitives (small straddlers held by several children) are drawn once
//!   per frame and instance: §3.1's frame stamp, kept as one bit per shared primitive in a bit
//!   set per instance that draws one this frame.
//! - **Max z-pyramid and the box-face test (§3.2)**, [`occult_raster::ZPyramid`] and
//!   `boxtest`: a box at most 16 pixels wide and tall on screen is tested whole (Greene et al.:
//!   the rectangle of its eight corners at their nearest depth, one pyramid test; as many boxes
//!   culled on the suite's views, the `city:blocks=32` orbit's first frame's tests 27 %
//!   cheaper); a larger one face by face: each front face is tested at the finest pyramid
//!   level where the face's screen box meets at most 2×2 samples (Greene et al.), descending
//!   where the comparison fails down to the frame's own depth (a failing sample wholly inside
//!   the box ends the test). Our depth is reversed, so the paper's max pyramid is a min pyramid over
//!   stored depth (see the pyramid's doc).
//! - **Pyramid updates: per batch.** Visible geometry is gathered into batches of about `batch`
//!   triangles; a full batch is rasterized (multi-threaded) and the pyramid is then recomputed
//!   over the box of the batch's triangles that wrote a fragment
//!   ([`occult_raster::Rasterizer::take_written`]; nothing when the batch was wholly hidden).
//!   Per triangle would cost more than the triangle;
//!   per batch amortizes the update and keeps the rasterizer's batches large. Correctness does
//!   not depend on the schedule: depth only grows during a frame, so a stale pyramid can only
//!   fail to reject (the test's last level reads the frame itself). The visible list, which
//!   nothing tests, is drawn in batches large enough for the rasterizer's threads, the pyramid
//!   updated once after it. Addition, `refresh`: a test that fails while the pending batch
//!   (at least `refresh` triangles) meets the box on screen draws the batch and tests again:
//!   in a front-to-back walk the batch often holds the box's occluder (the near side of the
//!   same building), which a full-size batch would leave out of the pyramid.
//! - **Node draws as clusters** (not in the paper): a mesh octree node's unshared own triangles
//!   are kept as clusters of at most 256 distinct vertices ([`occult_raster::Meshlets`], built
//!   once with the octrees), so drawing the node projects each vertex once instead of three
//!   corners a triangle; its shared ones, drawn once a frame by their stamps, stay an index list.
//! - **Front-to-back traversal**: children of an octree node in the order of the octants seen
//!   from the eye; a node's box is tested (frustum, then occlusion) before its own primitives
//!   are drawn and its children visited.
//! - **Temporal coherence (§3.3)**: the nodes whose primitives were drawn last frame (the
//!   *visible list*) are drawn first, without tests, to make the depth buffer "almost
//!   complete"; then the whole hierarchy is traversed with tests (skipping what the list drew).
//!   At frame end the list is rechecked against the final depth and pruned; `recheck=N` does
//!   that only every N frames (§4.2, §5.1). Nodes first drawn this frame join the list (a
//!   group's node only when one of its small meshes was drawn, not merely reached).
//! - **Ordering heuristics**: the visible list in descending projected screen area (§4.2,
//!   `area_sort`); frustum-culled list entries keep their visible status (§5.1, `keep_culled`);
//!   `order=count` visits siblings in ascending primitive count instead of front to back
//!   (§4.2/§5.1's invisible list; see the deviations).
//! - **Global farthest-depth reject (§5.3)**, `global`: the pyramid's top sample, compared first.
//! - **Parallel distributions (§4.1)**, `parallel=structure|primitive|hybrid`, `workers=N`:
//!   each worker thread walks its share of the scene with its own frame (depth buffer), pyramid,
//!   visible list and single-threaded rasterizer; the frames are merged by depth compositing
//!   under the (depth, item) rule. *By structure*: the root's primitives (whole subtrees)
//!   round robin; *by primitive*: every worker walks every node and draws a round-robin share
//!   of each node's primitives (and pays every box test); *hybrid*: structures kept whole but
//!   fine (octree nodes of every instance) spread over the workers by a hash. Each worker's busy
//!   time and its idle time (waiting for the slowest before the merge) are reported as the
//!   counters `worker<k>_busy_us` / `worker<k>_idle_us`; the phases are the slowest worker's,
//!   the merge is `other`.
//! - **Sort-first by columns** (not in the paper), `parallel=columns`, `strips=N`: the screen
//!   is cut into `workers × N` strips of columns, handed out one at a time (last frame's
//!   slowest first) to whichever worker is free; a worker culls and draws a strip as a view
//!   restricted to its columns, in its own frame (blocked beside them), pyramid and one
//!   rasterizer thread, with the strip's own visible list and payoff, then copies the strip's
//!   columns into the frame (no merge). Unlike `bands=N`, which copies the whole renderer per
//!   band, the octrees are shared and the frame-level choice of [`crate::direct`] is the
//!   renderer's: a direct frame is drawn whole, on all threads; each strip's in-frame payoff
//!   weighs its share of the work against its share of that frame. The cuts move after each
//!   frame towards an even split of the strips' times ([`crate::bands::ColumnShare`]). The
//!   phases add the strips' thread times, the copies are `other`; `visible_list_precision_pct`
//!   is their mean, `strips` counts them. `parallel=auto`, the default, takes the columns
//!   on scenes of at least [`AUTO_COLUMNS`] triangle instances drawn on two threads or more,
//!   and one walk otherwise: a culled frame of one walk rasterizes its small batches on one
//!   thread, which a frame of millions of triangles cannot afford on two cores, while on the
//!   suite's scenes of 1-5 M triangles the strips' fixed part costs more than it gains.
//!
//! - **Payoff** ([`crate::payoff`], `payoff`): a frame whose tests cost more than they save
//!   stops testing and draws the rest directly: mesh instances wholly in view whole, in batches
//!   large enough for the rasterizer's threads, without pyramid updates (only the recheck reads
//!   the pyramid then, and it rebuilds it). Across frames ([`crate::direct`], without a
//!   distribution): after a frame that was slower than a measured direct frame (`frustum`'s
//!   way, per triangle in view), runs of frames are drawn directly (counter `payoff_direct`),
//!   culling probed between them; a frame headed for more than a direct frame's time (at its
//!   pace so far) is given up: it stops testing and draws the rest directly, keeping what it
//!   drew ([`crate::payoff::FramePayoff::given_up`]).
//!
//! Every part has a switch so its effect can be measured (`occult algos` lists them).
//!
//! # Deviations from the paper
//! - §4's processors are threads of one machine sharing memory: the distributions are
//!   per-frame filters over the shared octrees rather than copies of the data, and every
//!   worker of `structure`/`hybrid` still walks (and tests) the shared upper octree levels.
//!   With `parallel=off` (what `auto`, the default, takes below 8 M triangle instances)
//!   parallelism is the rasterizer's own: sort-last within a batch of at least 200,000
//!   triangles; a shorter batch that its measured cost of a triangle makes long is shared by
//!   bands of rows (its fill split over the threads, the setup repeated), the rest drawn on
//!   the calling thread.
//! - §3.1's hybrid redistribution is off by default (`small=0`; the paper's value is
//!   `small=0.25`): a straddler stays at its cell, tested with the cell's own primitives
//!   (below). Shared straddlers cost a stamp check each and are drawn as an index list, the
//!   others as clusters; their tighter boxes did not pay that back. Frame 0 of the suite's
//!   `forest` orbit, one thread, `payoff=off,temporal=off`: 180 ms with `small=0.25`,
//!   91 ms with `small=0` (`zbuffer`: 68 ms); the suite's `plant` orbit is 5-10 % slower.
//! - Two additions beyond the paper, both conservative: an inner octree node's own primitives
//!   (its large straddlers) are tested against their own box before they are drawn, and the
//!   instances held by one node of a group's octree are visited nearest first (the octants
//!   give the order between nodes, not within one).
//! - Addition, `retest`: a visible-list entry kept while outside the frustum (§5.1) is never
//!   rechecked there, so when it comes back into view (a street corner turned) its status is
//!   many frames old; it is then box-tested before it is drawn (and stays off the list when
//!   hidden). Entries seen last frame are still drawn untested (§3.3) while the list is
//!   precise enough (next).
//! - Addition, `trust`: §3.3 assumes frame-to-frame coherence. Where the view moves far between
//!   frames (an orbit in 8 steps), much of last frame's list is hidden now, and drawing it
//!   untested submits more than the tested traversal alone would (an 8-step orbit of
//!   `city:blocks=32`: 15 M triangles a frame against 9.3 M for the first, with no list; the
//!   suite's `street:16` of that city jumps between streets, and 0-1 % of a list stays
//!   visible there).
//!   The recheck measures the list's precision: the share of the triangles of last frame's
//!   entries in view that are still visible at the frame's end. Below `trust`, the next frame
//!   does not draw the entries in view (it notes them, so that its recheck measures the
//!   precision again) and the tested traversal alone draws the frame; the counter
//!   `visible_list_skipped` says how many were skipped, `visible_list_precision_pct` the
//!   precision measured. A frame that skipped the list measures first the share of the
//!   skipped triangles its traversal drew (an upper bound of the precision); below `trust`, it
//!   skips the recheck too, the next frame skipping the list anyway. Box-testing the entries
//!   instead of skipping them measured slower (in descending screen area they are not front
//!   to back, and the traversal tests the hidden ones again). A list of moderate precision
//!   still pays, drawing the occluders first: on `plant`'s 32-step orbit 51-93 % of the list
//!   stays visible, and skipping it below 75 % rasterized twice the triangles; hence the
//!   default 0.4.
//! - Addition, `weigh`: the precision cannot tell every case (the 8-step orbit of
//!   `city:blocks=32` keeps 56-71 % of its list, `plant`'s 32-step orbit 51-93 %, and the list
//!   costs the first and pays on the second), so the frame times decide as well: the list is
//!   drawn only while the last frame that drew it was faster than the last that did not (the
//!   first frame, which has none, is one), the way not taken measured again after 16, 32, 64
//!   frames ([`crate::list_choice`]). Each strip of `parallel=columns` chooses for itself.
//! - Addition, `payoff` (above): the paper tests everything; on views where little is hidden
//!   that is slower than brute force.
//! - Addition, `whole`: a mesh instance whose visible-list nodes hold at least this fraction of
//!   its triangles is drawn whole, as one whole-mesh draw, and the tested traversal skips it
//!   this frame; its entries stay listed and are rechecked, so when the visible share falls
//!   below the fraction it is walked again. Mostly-visible instances (city overviews) then
//!   cost one draw whose vertices are projected once, in parallel, instead of dozens of
//!   index lists and their box tests. Conservative: it draws a superset.
//! - By structure over a scene whose root is a mesh degenerates to by primitive (the root's
//!   primitives are then triangles).
//! - The invisible list of §4.2/§5.1 is flat in the paper (structures sorted by primitive count
//!   as a preprocess). Here the not-yet-visible part of the scene is the octree itself, walked
//!   from the root; `order=count` applies the heuristic where an order is chosen: among the
//!   children of a node (ascending subtree primitive count).
//! - The visible list holds octree nodes (per instance of their DAG node), not the paper's flat
//!   structures; a listed node's own primitives are drawn, its children are handled by their
//!   own entries.
//! - The box test reads the frame's depth (conservatively) rather than rasterizing the faces;
//!   a face is compared over its screen bounding box, as the paper's Fig. 2 starts.
//!
//! The tested traversal is the crate's scene walk ([`crate::walk`]) without a test of a DAG
//! node's own box: an instance with an octree starts at its octree's root (tested there), a
//! small mesh is tested as one box; transforms and item ids come from the walk.
//!
//! Cost per frame: O(visible list + visited nodes × test + pyramid updates over drawn regions)
//! plus rasterizing what survives. It pays off on scenes of high depth complexity (cities,
//! plants); on open terrain almost everything is visible and the tests are pure overhead.

pub(crate) mod boxtest;
mod walk;

use std::sync::Arc;
use std::time::Instant;

use occult_core::{Affine3A, NodeId, NodeKind, Scene, View};
use occult_raster::{Frame, Rasterizer, ZPyramid};
use occult_spatial::{HybridOctree, HybridOctreeConfig};

use crate::columns::{Columns, StripWorker, BUSY, IDLE, STRIPS};
use crate::direct::DirectFrames;
use crate::list_choice::ListChoice;
use crate::nodes::{instance_boxes, per_node, triangle_boxes};
use crate::payoff::Payoff;
use crate::runs::RunClusters;
use crate::{
    check_frame, AlgorithmInfo, FrameStats, ParamDoc, Params, Phase, RenderError, RenderOptions, Renderer, Result,
};

/// Order of siblings in the traversal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChildOrder {
    /// Octants nearest the eye first (Greene et al.).
    FrontToBack,
    /// Ascending primitive count: postpone the expensive subtrees (§4.2, §5.1).
    Count,
}

/// §4.1: how the scene is spread over worker threads, each with its own depth buffer,
/// z-pyramid and visible list; their frames are merged by depth compositing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Distribution {
    /// One walk; parallelism is the rasterizer's own.
    Off,
    /// Distribute by structure: the root's primitives (whole subtrees) round robin.
    Structure,
    /// Distribute by primitive: every worker walks every node and draws a round-robin share of
    /// each node's primitives.
    Primitive,
    /// The hybrid: structures kept whole, but fine (octree nodes), spread over the workers.
    Hybrid,
    /// Sort-first by columns (not in the paper): each worker walks the whole scene for a view
    /// restricted to its columns of the screen ([`View::with_region`]), culling against its
    /// own depth of them; the columns are copied into the frame, no merge. The columns are
    /// shared again after each frame by the workers' times ([`crate::bands::ColumnShare`]).
    Columns,
    /// [`Distribution::Columns`] on a scene of at least [`AUTO_COLUMNS`] triangle instances
    /// drawn on two threads or more, else [`Distribution::Off`]; chosen when the renderer is
    /// built (see the module doc).
    Auto,
}

/// Triangle instances from which `parallel=auto` chooses the columns distribution.
pub use crate::columns::AUTO_COLUMNS;

impl Distribution {
    /// [`Distribution::Auto`] resolved for `scene` drawn on `threads` threads; others as they are.
    pub fn resolve(self, scene: &Scene, threads: usize) -> Self {
        match self {
            Self::Auto if crate::columns::auto_takes_columns(scene, threads) => Self::Columns,
            Self::Auto => Self::Off,
            d => d,
        }
    }
}

/// Deepest octree `hzb` accepts, in levels with the root as level 1 (its documented `depth`
/// range is 1..=32).
const MAX_DEPTH: u32 = 32;

/// Most workers of a distribution, and most strips of columns a worker under
/// [`Distribution::Columns`].
pub use crate::columns::{MAX_STRIPS, MAX_WORKERS};

/// Tunables of [`Hzb`]; every part can be switched off to measure it.
#[derive(Clone, Debug, PartialEq)]
pub struct HzbOptions {
    /// Octree build (§3.1): leaf size (triangles or instances), depth, small-straddler fraction.
    pub octree: HybridOctreeConfig,
    /// Triangles gathered before rasterizing and updating the pyramid (≥ 1).
    pub batch_triangles: usize,
    /// A test that fails while at least this many triangles are pending, over a screen region
    /// meeting the box's, draws them, updates the pyramid and tests again (0: never).
    pub refresh: usize,
    /// Occlusion tests at all (off: octree frustum culling only, and no visible list).
    pub occlusion: bool,
    /// Hierarchical pyramid test (§3.2); off: a full-resolution scan of each face's rectangle.
    pub pyramid: bool,
    /// Global farthest-depth early reject (§5.3).
    pub global: bool,
    /// Temporal coherence visible list (§3.3).
    pub temporal: bool,
    /// Recheck the visible list every this many frames (≥ 1) (§4.2, §5.1).
    pub recheck_every: u32,
    /// Draw the visible list in descending screen area (§4.2).
    pub area_sort: bool,
    /// Keep frustum-culled entries on the visible list (§5.1).
    pub keep_culled: bool,
    /// Box-test kept entries when they come back into the frustum, instead of drawing them
    /// untested (not in the paper).
    pub retest: bool,
    /// Draw a mesh instance whole when its visible-list nodes hold at least this fraction of
    /// its triangles (0: never). Not in the paper.
    pub whole: f32,
    /// Draw the visible list only when at least this fraction of the last list's triangles in
    /// view stayed visible (its precision at the last recheck); below it, the frame is drawn
    /// by the tested traversal alone (0: always drawn, as the paper). Not in the paper.
    pub trust: f32,
    /// Draw the visible list first only while frames that drew it were faster than frames
    /// that did not ([`crate::list_choice`]). Not in the paper.
    pub weigh: bool,
    /// Sibling order.
    pub order: ChildOrder,
    /// Parallel distribution (§4.1).
    pub distribution: Distribution,
    /// Workers of the distribution (1 ..= [`MAX_WORKERS`]; 0: the rasterizer's threads, at
    /// most [`MAX_WORKERS`]); each rasterizes on one thread.
    pub workers: usize,
    /// Under [`Distribution::Columns`], strips of columns a worker (1 ..= [`MAX_STRIPS`]),
    /// handed out one at a time to whichever worker is free.
    pub strips: usize,
    /// Stop testing for the rest of a frame once the tests cost more than they save, and draw
    /// the rest directly ([`crate::payoff`]); draw whole frames directly while culled frames
    /// are slower than direct ones ([`crate::direct`]). Not in the paper.
    pub payoff: bool,
}

impl Default for HzbOptions {
    fn default() -> Self {
        Self {
            octree: HybridOctreeConfig {
                leaf_size: 256,
                max_depth: 10,
                // Deviation: no redistribution by default (see the module doc).
                small_fraction: 0.0,
            },
            batch_triangles: 4096,
            refresh: 512,
            occlusion: true,
            pyramid: true,
            global: true,
            temporal: true,
            recheck_every: 1,
            area_sort: true,
            keep_culled: true,
            retest: true,
            whole: 0.5,
            trust: 0.4,
            weigh: true,
            order: ChildOrder::FrontToBack,
            distribution: Distribution::Auto,
            workers: 0,
            strips: 2,
            payoff: true,
        }
    }
}

impl HzbOptions {
    /// Reads and checks the settings of an `hzb:...` spec.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] naming the key for an unparsable or out-of-range value.
    pub fn from_params(p: &Params) -> Result<Self> {
        let d = Self::default();
        let bad = |m: String| Err(RenderError::BadParameter(format!("hzb: {m}")));
        let leaf_size: usize = p.get("leaf", d.octree.leaf_size)?;
        if leaf_size == 0 {
            return bad("leaf=0: a leaf holds at least 1 primitive".into());
        }
        let max_depth: u32 = p.get("depth", d.octree.max_depth)?;
        if max_depth == 0 || max_depth > MAX_DEPTH {
            return bad(format!("depth={max_depth}: octree depth must be in 1..={MAX_DEPTH}"));
        }
        let small_fraction: f32 = p.get("small", d.octree.small_fraction)?;
        if !(0.0..=1.0).contains(&small_fraction) {
            return bad(format!(
                "small={small_fraction}: the small-straddler fraction must be in [0, 1]"
            ));
        }
        let batch_triangles: usize = p.get("batch", d.batch_triangles)?;
        if batch_triangles == 0 || batch_triangles > 1 << 24 {
            return bad(format!(
                "batch={batch_triangles}: triangles per batch must be in 1..=16777216"
            ));
        }
        let refresh: usize = p.get("refresh", d.refresh)?;
        let recheck: i64 = p.get("recheck", d.recheck_every as i64)?;
        if !(1..=1_000_000).contains(&recheck) {
            return bad(format!(
                "recheck={recheck}: the visible list is rechecked every N frames, N in 1..=1000000"
            ));
        }
        let whole: f32 = p.get("whole", d.whole)?;
        if !(0.0..=1.0).contains(&whole) {
            return bad(format!(
                "whole={whole}: the fraction of a mesh listed visible for drawing it whole must be in [0, 1]"
            ));
        }
        let trust: f32 = p.get("trust", d.trust)?;
        if !(0.0..=1.0).contains(&trust) {
            return bad(format!(
                "trust={trust}: the share of the visible list that must stay visible for drawing it first must be in [0, 1]"
            ));
        }
        let occlusion = p.flag("occlusion", d.occlusion)?;
        // `threads` (the default): the rasterizer's threads, 0 until the renderer is built.
        let workers: usize = match p.raw("workers") {
            None => d.workers,
            Some(v) if v.eq_ignore_ascii_case("threads") => d.workers,
            Some(v) => match v.parse::<usize>() {
                Ok(n) if (1..=MAX_WORKERS).contains(&n) => n,
                _ => return bad(format!("workers={v}: workers must be in 1..={MAX_WORKERS}, or threads")),
            },
        };
        let strips: usize = p.get("strips", d.strips)?;
        if strips == 0 || strips > MAX_STRIPS {
            return bad(format!("strips={strips}: strips a worker must be in 1..={MAX_STRIPS}"));
        }
        Ok(Self {
            distribution: match p.choice(
                "parallel",
                &["auto", "off", "structure", "primitive", "hybrid", "columns"],
                "auto",
            )? {
                "structure" => Distribution::Structure,
                "primitive" => Distribution::Primitive,
                "hybrid" => Distribution::Hybrid,
                "columns" => Distribution::Columns,
                "off" => Distribution::Off,
                _ => Distribution::Auto,
            },
            workers,
            strips,
            payoff: p.flag("payoff", d.payoff)?,
            octree: HybridOctreeConfig {
                leaf_size,
                max_depth,
                small_fraction,
            },
            batch_triangles,
            refresh,
            occlusion,
            pyramid: p.flag("pyramid", d.pyramid)?,
            global: p.flag("global", d.global)?,
            // Without occlusion tests the order of drawing changes nothing: no visible list.
            temporal: occlusion && p.flag("temporal", d.temporal)?,
            recheck_every: recheck as u32,
            area_sort: p.flag("area_sort", d.area_sort)?,
            keep_culled: p.flag("keep_culled", d.keep_culled)?,
            retest: p.flag("retest", d.retest)?,
            whole,
            trust,
            weigh: p.flag("weigh", d.weigh)?,
            order: match p.choice("order", &["front", "count"], "front")? {
                "count" => ChildOrder::Count,
                _ => ChildOrder::FrontToBack,
            },
        })
    }
}

/// Every counter ([`FrameStats::counters`](crate::FrameStats::counters)) a frame may report,
/// whichever the settings, except the per-worker ones of `parallel=on` (`worker<k>_busy_us`,
/// `worker<k>_idle_us`); [`INFO`]'s counters list those too.
pub const COUNTERS: [&str; 22] = [
    "occlusion_tests",
    "occlusion_culled",
    "frustum_culled",
    "pyramid_tests",
    "pyramid_descents",
    "global_rejects",
    "visible_list",
    "visible_list_drawn",
    "visible_list_frustum_culled",
    "recheck_dropped",
    "batches",
    "whole_drawn",
    "visible_list_retested",
    "visible_list_skipped",
    PRECISION,
    "refreshes",
    "refreshes_paid",
    crate::payoff::COUNTERS[0],
    crate::payoff::COUNTERS[1],
    crate::direct::COUNTER,
    crate::direct::SCREENED,
    STRIPS,
];

/// Every counter a frame may report: [`COUNTERS`], then the workers' busy and idle times.
const DECLARED: [&str; COUNTERS.len() + 2 * MAX_WORKERS] = crate::columns::declared(&COUNTERS);

/// Registry entry of [`Hzb`].
pub static INFO: AlgorithmInfo = AlgorithmInfo {
    name: "hzb",
    summary: "hierarchical z-buffer obscuration culling: octree, max z-pyramid, temporal coherence (Georges 1995)",
    params: &[
        ParamDoc {
            key: "leaf",
            default: "256",
            help: "octree leaf size in primitives (triangles or instances), >= 1 (§3.1)",
        },
        ParamDoc {
            key: "depth",
            default: "10",
            help: "octree depth limit in levels, 1..=32 (§3.1)",
        },
        ParamDoc {
            key: "small",
            default: "0",
            help:
                "hybrid redistribution: straddlers at most this fraction of the cell go to every child, 0 = off (§3.1; the paper's 0.25 is slower here)",
        },
        ParamDoc {
            key: "batch",
            default: "4096",
            help: "triangles rasterized per batch, after which the z-pyramid is updated (§3.2)",
        },
        ParamDoc {
            key: "refresh",
            default: "512",
            help: "a failed test draws the pending batch early and tests again when it holds at least this many triangles over the box's screen region, 0 = never (not in the paper)",
        },
        ParamDoc {
            key: "occlusion",
            default: "on",
            help: "occlusion tests at all (off: octree frustum culling only, no visible list)",
        },
        ParamDoc {
            key: "pyramid",
            default: "on",
            help: "hierarchical z-pyramid test (§3.2); off: full-resolution scan of each face's rectangle",
        },
        ParamDoc {
            key: "global",
            default: "on",
            help: "early reject against the frame's farthest depth (§5.3)",
        },
        ParamDoc {
            key: "temporal",
            default: "on",
            help: "draw last frame's visible list first (§3.3)",
        },
        ParamDoc {
            key: "recheck",
            default: "1",
            help: "prune the visible list against the final depth every N frames, N >= 1 (§3.3, §5.1)",
        },
        ParamDoc {
            key: "area_sort",
            default: "on",
            help: "draw the visible list in descending projected screen area (§4.2)",
        },
        ParamDoc {
            key: "keep_culled",
            default: "on",
            help: "frustum-culled nodes keep their visible status (§5.1)",
        },
        ParamDoc {
            key: "retest",
            default: "on",
            help: "visible-list entries kept while outside the frustum are box-tested when they return, not drawn untested; needs temporal (not in the paper)",
        },
        ParamDoc {
            key: "whole",
            default: "0.5",
            help: "draw a mesh instance whole when its visible-list nodes hold at least this fraction of its triangles, 0 = never; needs temporal (not in the paper)",
        },
        ParamDoc {
            key: "trust",
            default: "0.4",
            help: "draw the visible list first only while at least this share of the last list (in triangles) stayed visible, else let the tested traversal draw the frame alone; 0 = always (§3.3); needs temporal (not in the paper)",
        },
        ParamDoc {
            key: "weigh",
            default: "on",
            help: "draw the visible list first only while frames that drew it were faster than frames that did not (the last of each; the other way measured again after 16, 32, 64 frames); off = by trust alone; needs temporal (not in the paper)",
        },
        ParamDoc {
            key: "order",
            default: "front",
            help: "sibling order: front (front to back) or count (ascending primitive count, §4.2/§5.1)",
        },
        ParamDoc {
            key: "parallel",
            default: "auto",
            help: "distribution over workers with own depth buffers: off, structure, primitive, hybrid (§4.1, merged by depth compositing), columns (each worker culls and draws its columns of the screen; not in the paper), auto (columns on scenes of at least 8,000,000 triangle instances drawn on 2 threads or more, else off)",
        },
        ParamDoc {
            key: "workers",
            default: "threads",
            help: "workers of the distribution, 1..=8 (each rasterizes on one thread), or threads: the rasterizer's threads, at most 8",
        },
        ParamDoc {
            key: "strips",
            default: "2",
            help: "parallel=columns: strips of columns a worker, 1..=16, handed out one at a time to whichever worker is free",
        },
        ParamDoc {
            key: "payoff",
            default: "on",
            help: "stop testing for the rest of a frame once tests cost more than they save, and draw the rest directly; draw runs of frames as frustum does while culled frames are slower than such direct frames (not in the paper)",
        },
    ],
    counters: &DECLARED,
    conservative: true,
    bands: true,
    build: |scene, options, params| Ok(Box::new(Hzb::new(scene, options, &HzbOptions::from_params(params)?)?)),
};

/// An entry of the visible list: one octree node of one instance of a DAG node.
#[derive(Clone, Copy, Debug)]
struct VisEntry {
    dag_node: NodeId,
    octree_node: u32,
    first_item: u64,
    world_from_node: Affine3A,
    /// Listed while outside the frustum (§5.1), so not rechecked since it was last seen.
    stale: bool,
}

/// What one walker keeps across frames: its rasterizer, pyramid and visible list (and, for a
/// worker of a distribution, its own frame).
struct Worker {
    raster: Rasterizer,
    payoff: Payoff,
    stamps: walk::Stamps,
    frame: Option<Frame>,
    pyramid: Option<ZPyramid>,
    visible: Vec<VisEntry>,
    /// Whether the next frame draws the visible list first (`trust`, `weigh`).
    list_way: ListWay,
}

impl StripWorker for Worker {
    fn raster(&mut self) -> &mut Rasterizer {
        &mut self.raster
    }

    fn ready(&mut self, width: u32, height: u32) -> Result<bool> {
        if !matches!(&self.frame, Some(f) if f.width() == width && f.height() == height) {
            self.frame = None;
            self.frame = Some(Frame::new(width, height)?);
            self.pyramid = None;
        }
        let made = !matches!(&self.pyramid, Some(p) if p.width() == width && p.height() == height);
        if made {
            self.pyramid = Some(ZPyramid::new(width, height)?);
        }
        Ok(made)
    }

    fn frame(&self) -> &Frame {
        match &self.frame {
            Some(f) => f,
            None => unreachable!("made by `ready` before a strip is drawn"),
        }
    }
}

impl Worker {
    fn memory_bytes(&self) -> usize {
        self.pyramid.as_ref().map_or(0, ZPyramid::memory_bytes)
            + self.frame.as_ref().map_or(0, Frame::memory_bytes)
            + self.visible.capacity() * std::mem::size_of::<VisEntry>()
            + self.stamps.memory_bytes()
            + self.raster.memory_bytes()
    }
}

/// Per DAG node, what the walk reads beside its octree.
struct PerNode {
    /// Per DAG node with an octree: triangle instances below each of its nodes (what a test
    /// that culls the node saves, [`crate::payoff`]).
    subtree_items: Vec<Vec<u64>>,
    /// Per mesh with an octree: its nodes' unshared triangles as clusters, a run per node.
    meshlets: Vec<Option<RunClusters>>,
}

/// The hzb renderer.
pub struct Hzb {
    scene: Arc<Scene>,
    options: HzbOptions,
    /// Per DAG node: its octree (groups, and meshes over the leaf size).
    octrees: Vec<Option<HybridOctree>>,
    /// What the walk reads beside the octrees.
    per_node: PerNode,
    /// One walker, or one per worker of the distribution.
    workers: Vec<Worker>,
    frames_since_recheck: u32,
    /// Frames drawn directly where culling does not pay (`payoff=on`).
    direct: Option<DirectFrames>,
    /// The rasterizer of direct frames under the columns distribution (on all threads; the
    /// workers' rasterize on one each).
    direct_raster: Option<Rasterizer>,
    /// The strips of the columns distribution (none under the others).
    columns: Columns<StripState>,
}

/// What a strip of columns of [`Distribution::Columns`] keeps from frame to frame besides its
/// payoff, whichever worker draws it.
struct StripState {
    visible: Vec<VisEntry>,
    list_way: ListWay,
}

/// What decides whether a frame draws the visible list first: its precision at the last
/// recheck (`trust`) and the time of frames with it and without it (`weigh`).
#[derive(Clone, Copy, Debug)]
struct ListWay {
    precision: f64,
    choice: ListChoice,
    /// The list was rechecked (or is empty) at the end of the frame that made it.
    pruned: bool,
    /// The frame that made it drew the list before it.
    drew: bool,
}

impl Default for ListWay {
    fn default() -> Self {
        Self {
            precision: 1.0,
            choice: ListChoice::default(),
            pruned: true,
            drew: false,
        }
    }
}

/// The counter of the visible list's precision at the last recheck, percent.
pub(crate) const PRECISION: &str = "visible_list_precision_pct";

/// Ensures `slot` holds a pyramid of the frame's size, cleared.
fn ready_pyramid(slot: &mut Option<ZPyramid>, width: u32, height: u32) -> Result<&mut ZPyramid> {
    if matches!(slot, Some(p) if p.width() == width && p.height() == height) {
        if let Some(p) = slot.as_mut() {
            p.clear();
        }
    } else {
        *slot = Some(ZPyramid::new(width, height)?);
    }
    match slot {
        Some(p) => Ok(p),
        None => unreachable!("set just above"),
    }
}

impl Hzb {
    /// Builds the octrees of `scene`.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for out-of-range options; raster configuration errors.
    pub fn new(scene: Arc<Scene>, options: &RenderOptions, hzb: &HzbOptions) -> Result<Self> {
        let o = &hzb.octree;
        if o.leaf_size == 0 || o.max_depth == 0 || o.max_depth > MAX_DEPTH || !(0.0..=1.0).contains(&o.small_fraction) {
            return Err(RenderError::BadParameter(format!(
                "hzb: bad octree configuration {o:?}"
            )));
        }
        if hzb.batch_triangles == 0 || hzb.recheck_every == 0 {
            return Err(RenderError::BadParameter(
                "hzb: batch and recheck must be at least 1".into(),
            ));
        }
        let raster = crate::scene_rasterizer(&scene, options)?;
        let mut hzb = hzb.clone();
        hzb.distribution = hzb.distribution.resolve(&scene, raster.thread_count());
        if hzb.workers == 0 {
            hzb.workers = raster.thread_count().clamp(1, MAX_WORKERS);
        }
        if hzb.workers > MAX_WORKERS || !(1..=MAX_STRIPS).contains(&hzb.strips) {
            return Err(RenderError::BadParameter(format!(
                "hzb: {} workers and {} strips a worker: expected 1..={MAX_WORKERS} and 1..={MAX_STRIPS}",
                hzb.workers, hzb.strips
            )));
        }
        let octrees: std::result::Result<Vec<Option<HybridOctree>>, _> =
            per_node(&raster, &scene, |node| match node.kind() {
                NodeKind::Mesh(m) if m.triangle_count() > o.leaf_size => {
                    HybridOctree::build(&triangle_boxes(m), o).map(Some)
                }
                NodeKind::Group(g) if !g.is_empty() => HybridOctree::build(&instance_boxes(&scene, g), o).map(Some),
                _ => Ok(None),
            });
        let octrees = octrees.map_err(|e| RenderError::BadParameter(format!("hzb: {e}")))?;
        let meshlets = scene
            .nodes()
            .iter()
            .zip(&octrees)
            .map(|(node, o)| match (node.kind(), o) {
                (NodeKind::Mesh(m), Some(o)) => node_clusters(m, o).map(Some),
                _ => Ok(None),
            })
            .collect::<Result<Vec<_>>>()?;
        let workers = if hzb.distribution == Distribution::Off {
            vec![Worker {
                payoff: Payoff::new(hzb.payoff, scene.item_count()),
                raster,
                frame: None,
                pyramid: None,
                visible: Vec::new(),
                list_way: ListWay::default(),
                stamps: walk::Stamps::new(&octrees),
            }]
        } else {
            let one = occult_raster::RasterConfig {
                threads: 1,
                ..options.raster.clone()
            };
            (0..hzb.workers)
                .map(|_| {
                    Ok(Worker {
                        raster: Rasterizer::new(one.clone())?,
                        payoff: Payoff::new(hzb.payoff, scene.item_count()),
                        frame: None,
                        pyramid: None,
                        visible: Vec::new(),
                        list_way: ListWay::default(),
                        stamps: walk::Stamps::new(&octrees),
                    })
                })
                .collect::<Result<Vec<_>>>()?
        };
        let subtree_items = octrees
            .iter()
            .enumerate()
            .map(|(i, o)| {
                o.as_ref()
                    .map_or_else(Vec::new, |o| subtree_items(&scene, NodeId(i as u32), o))
            })
            .collect();
        hzb.temporal &= hzb.occlusion; // without tests a visible list changes nothing
                                       // Direct frames go through the walker's rasterizer, or under the columns
                                       // distribution one of their own on all threads; not under the other
                                       // distributions, whose workers rasterize on one thread each.
        let (direct, direct_raster) = match (hzb.payoff, hzb.distribution) {
            (true, Distribution::Off) => (Some(DirectFrames::new(scene.clone(), &workers[0].raster)?), None),
            (true, Distribution::Columns) => {
                let raster = crate::scene_rasterizer(&scene, options)?;
                // Not `culled_on(workers)`: weighed at the strips' cost of a triangle in thread
                // time, the culled frames that win on `city:blocks=32`'s orbit are kept
                // (measured, two runs: 1.32 and 1.23× `zbuffer`; 1.09 and 0.94× weighed in
                // wall time, which sent them to direct frames).
                (Some(DirectFrames::new(scene.clone(), &raster)?), Some(raster))
            }
            _ => (None, None),
        };
        let strips = match hzb.distribution {
            Distribution::Columns => hzb.workers * hzb.strips,
            _ => 0,
        };
        let columns = Columns::new(strips, || {
            let state = StripState {
                visible: Vec::new(),
                list_way: ListWay::default(),
            };
            (state, Payoff::new(hzb.payoff, scene.item_count()))
        });
        Ok(Self {
            direct,
            direct_raster,
            columns,
            scene,
            options: hzb,
            per_node: PerNode {
                subtree_items,
                meshlets,
            },
            octrees,
            workers,
            frames_since_recheck: 0,
        })
    }
}

/// The unshared own triangles of every node of the octree of `mesh` as clusters, a run per
/// node (the shared ones are drawn once a frame by their stamps, as an index list).
fn node_clusters(mesh: &occult_core::Mesh, octree: &HybridOctree) -> Result<RunClusters> {
    let mut triangles = Vec::with_capacity(octree.primitive_count());
    let mut starts = Vec::with_capacity(octree.nodes().len() + 1);
    starts.push(0);
    for n in 0..octree.nodes().len() as u32 {
        triangles.extend(octree.node_primitives(n).iter().filter(|&&p| !octree.is_shared(p)));
        starts.push(triangles.len() as u32);
    }
    RunClusters::build(mesh, &triangles, starts)
}

/// Triangle instances below each node of `octree`, the octree of DAG node `id`: its own
/// primitives' (triangles of a mesh, the instances' triangles of a group) and its children's.
fn subtree_items(scene: &Scene, id: NodeId, octree: &HybridOctree) -> Vec<u64> {
    let nodes = octree.nodes();
    let per_primitive = |p: u32| match scene.node(id).kind() {
        NodeKind::Mesh(_) => 1,
        NodeKind::Group(g) => scene.node(g[p as usize].child).item_count(),
    };
    let mut items = vec![0u64; nodes.len()];
    // Post-order without recursion: a node is summed after all its children.
    let mut stack = vec![(0u32, false)];
    while let Some((n, done)) = stack.pop() {
        let node = &nodes[n as usize];
        let children = node
            .children
            .iter()
            .copied()
            .filter(|&c| c != occult_spatial::octree::hybrid::NO_CHILD);
        if done {
            let own: u64 = octree.node_primitives(n).iter().map(|&p| per_primitive(p)).sum();
            items[n as usize] = own + children.map(|c| items[c as usize]).sum::<u64>();
        } else {
            stack.push((n, true));
            stack.extend(children.map(|c| (c, false)));
        }
    }
    items
}

/// One walk over (the share of) the scene: visible list, tested traversal, recheck.
#[allow(clippy::too_many_arguments)]
fn walk_frame(
    scene: &Scene,
    octrees: &[Option<HybridOctree>],
    options: &HzbOptions,
    view: &View,
    raster: &mut Rasterizer,
    frame: &mut Frame,
    pyramid: &mut ZPyramid,
    visible: &mut Vec<VisEntry>,
    way: &mut ListWay,
    share: walk::Share,
    recheck: bool,
    stamps: &mut walk::Stamps,
    per_node: &PerNode,
    payoff: &mut Payoff,
) -> FrameStats {
    let start = Instant::now();
    let old_visible = std::mem::take(visible);
    // What the rasterizer wrote before this walk (a direct frame, another strip) is no batch's.
    let _ = raster.take_written();
    let mut w = walk::Walk::new(
        scene, octrees, options, view, raster, frame, pyramid, share, stamps, per_node, payoff,
    );
    let skip = way.precision < options.trust as f64 || (options.weigh && way.choice.skip());
    if options.temporal {
        w.draw_visible_list(old_visible, skip);
    }
    w.traverse();
    let mut pruned = false;
    if recheck {
        // A skipped list that the traversal mostly did not draw is skipped next frame too:
        // no recheck is needed to tell (`trust`).
        match w.skipped_drawn_share() {
            Some(p) if p < options.trust as f64 => way.precision = p,
            _ => {
                pruned = true;
                if let Some(p) = w.recheck() {
                    way.precision = p;
                }
            }
        }
    }
    let (list, stats) = w.finish();
    if options.weigh && options.temporal {
        let c = &stats.counters;
        let drew = c.get("visible_list_drawn") + c.get("whole_drawn") > 0;
        // A list made by a frame that neither drew nor pruned one (skipped unrechecked) holds
        // nodes hidden at that frame's end: drawing it is not what the list costs, and the
        // frame is not recorded (a probe of the list then lasts two frames). A list carried
        // over unpruned between rechecks (`recheck` above 1) is the list's steady state, and
        // is. A frame that stopped testing is recorded too: its time is what its way cost.
        if !drew || way.pruned || way.drew {
            way.choice.record(drew, start.elapsed());
        }
        way.drew = drew;
    }
    way.pruned = pruned || list.is_empty();
    *visible = list;
    stats
}

impl Hzb {
    /// §4.1: every worker walks its share into its own frame (own depth buffer, pyramid and
    /// lists, one rasterizer thread); the frames are then merged by depth compositing under the
    /// frame's (depth, item) rule, which makes the result that of one frame holding everything.
    /// Each worker's busy time is recorded, and its idle time: how long it waits for the
    /// slowest before the merge (the load balance the paper discusses).
    fn render_distributed(&mut self, view: &View, frame: &mut Frame, recheck: bool) -> Result<FrameStats> {
        let (scene, octrees, options) = (&*self.scene, &self.octrees[..], &self.options);
        let per_node = &self.per_node;
        let (width, height) = (frame.width(), frame.height());
        for w in &mut self.workers {
            if !matches!(&w.frame, Some(f) if f.width() == width && f.height() == height) {
                w.frame = Some(Frame::new(width, height)?);
            }
            ready_pyramid(&mut w.pyramid, width, height)?;
        }
        let n = self.workers.len() as u32;
        let results: Vec<(FrameStats, std::time::Duration)> = std::thread::scope(|s| {
            let handles: Vec<_> = self
                .workers
                .iter_mut()
                .enumerate()
                .map(|(k, w)| {
                    s.spawn(move || {
                        let t = Instant::now();
                        let (Some(f), Some(p)) = (w.frame.as_mut(), w.pyramid.as_mut()) else {
                            unreachable!("frames and pyramids were made above");
                        };
                        w.raster.clear(f);
                        let share = walk::Share {
                            distribution: options.distribution,
                            workers: n,
                            index: k as u32,
                        };
                        let stats = walk_frame(
                            scene,
                            octrees,
                            options,
                            view,
                            &mut w.raster,
                            f,
                            p,
                            &mut w.visible,
                            &mut w.list_way,
                            share,
                            recheck,
                            &mut w.stamps,
                            per_node,
                            &mut w.payoff,
                        );
                        (stats, t.elapsed())
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                .collect()
        });
        let t = Instant::now();
        composite(frame, self.workers.iter().filter_map(|w| w.frame.as_ref()));
        let merge = t.elapsed();
        let slowest = results.iter().map(|r| r.1).max().unwrap_or_default();
        let mut stats = FrameStats::default();
        for (k, (s, busy)) in results.iter().enumerate() {
            stats.add_counts(s);
            stats.counters.merge(&s.counters);
            stats.counters.add(BUSY[k], busy.as_micros() as u64);
            stats.counters.add(IDLE[k], (slowest - *busy).as_micros() as u64);
            if *busy == slowest {
                // Phases of the critical path: the slowest worker's.
                stats.phases = s.phases.clone();
            }
        }
        stats.phases.add(Phase::Other, merge);
        Ok(stats)
    }
}

impl Hzb {
    /// Sort-first by columns ([`Distribution::Columns`], [`crate::columns`]): each strip of
    /// columns (`bands[k]`, the frame's view restricted to strip `k`'s columns) walked by a
    /// worker into its own frame, cleared over the strip and blocked beside it, with its own
    /// pyramid and one rasterizer thread, and the strip's own visible list and payoff. The
    /// phases add the strips' thread times; what a strip's walk did not time is its culling.
    ///
    /// Also returns how long making the workers' frames and pyramids took (at the first frame
    /// or a new size; the slowest worker's): a one-time cost that the frame-level choice
    /// between culling and drawing directly does not weigh.
    fn render_columns(
        &mut self,
        frame: &mut Frame,
        recheck: bool,
        bands: &[View],
    ) -> Result<(FrameStats, std::time::Duration)> {
        let (scene, octrees, options, per_node) = (&*self.scene, &self.octrees[..], &self.options, &self.per_node);
        let workers = self.workers.iter_mut().collect();
        self.columns
            .render(workers, frame, bands, &[PRECISION], |w: &mut Worker, strip, band| {
                let t = Instant::now();
                let (Some(f), Some(p)) = (w.frame.as_mut(), w.pyramid.as_mut()) else {
                    unreachable!("made by `ready`");
                };
                let (_, _, cleared) = crate::begin_frame(&mut w.raster, band, f)?;
                p.clear_for(f);
                let mut stats = walk_frame(
                    scene,
                    octrees,
                    options,
                    band,
                    &mut w.raster,
                    f,
                    p,
                    &mut strip.state.visible,
                    &mut strip.state.list_way,
                    walk::Share::ALL,
                    recheck,
                    &mut w.stamps,
                    per_node,
                    &mut strip.payoff,
                );
                stats.phases.merge(&cleared.phases);
                // What the walk did not time is its culling.
                let p = &stats.phases;
                let accounted = p.get(Phase::Clear) + p.get(Phase::Raster) + p.get(Phase::DepthStructure);
                stats.phases.add(Phase::Cull, t.elapsed().saturating_sub(accounted));
                Ok(stats)
            })
    }
}

/// Depth compositing: every pixel of `out` takes the nearest fragment (ties to the smaller
/// item) of the `parts`, in row bands over the available threads.
fn composite<'f>(out: &mut Frame, parts: impl Iterator<Item = &'f Frame>) {
    let parts: Vec<&Frame> = parts.collect();
    let width = out.width() as usize;
    let (depth, items) = out.buffers_mut();
    depth.fill(occult_raster::CLEAR_DEPTH);
    items.fill(occult_core::NO_ITEM);
    use rayon::prelude::*;
    let rows = 16 * width;
    depth
        .par_chunks_mut(rows)
        .zip(items.par_chunks_mut(rows))
        .enumerate()
        .for_each(|(band, (d, it))| {
            let base = band * rows;
            for part in &parts {
                let (pd, pi) = (&part.depth()[base..base + d.len()], &part.items()[base..base + d.len()]);
                for j in 0..d.len() {
                    occult_raster::keep_fragment(&mut d[j], &mut it[j], pd[j], pi[j]);
                }
            }
        });
}

impl Renderer for Hzb {
    fn name(&self) -> &'static str {
        "hzb"
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        check_frame(view, frame)?;
        let start = Instant::now();
        let bands = match self.options.distribution {
            Distribution::Columns => self.columns.views(view, "hzb")?,
            _ => Vec::new(),
        };
        if let Some(direct) = &mut self.direct {
            let raster = self.direct_raster.as_mut().unwrap_or(&mut self.workers[0].raster);
            if let Some(stats) = direct.render_if_due(raster, view, frame)? {
                return crate::end_frame(raster, stats);
            }
            if bands.is_empty() {
                for w in &mut self.workers {
                    direct.arm(&mut w.payoff, w.raster.thread_count());
                }
            } else {
                self.columns.arm(direct, view, &bands, self.workers.len());
            }
        }
        self.frames_since_recheck += 1;
        let recheck = self.options.temporal && self.frames_since_recheck >= self.options.recheck_every;
        if recheck {
            self.frames_since_recheck = 0;
        }
        let (scene, octrees, options) = (&*self.scene, &self.octrees[..], &self.options);
        let mut setup = std::time::Duration::ZERO;
        let mut stats = if options.distribution == Distribution::Off {
            let w = &mut self.workers[0];
            let (_, _, cleared) = crate::begin_frame(&mut w.raster, view, frame)?;
            let pyramid = ready_pyramid(&mut w.pyramid, frame.width(), frame.height())?;
            pyramid.clear_for(frame);
            let mut stats = walk_frame(
                scene,
                octrees,
                options,
                view,
                &mut w.raster,
                frame,
                pyramid,
                &mut w.visible,
                &mut w.list_way,
                walk::Share::ALL,
                recheck,
                &mut w.stamps,
                &self.per_node,
                &mut w.payoff,
            );
            stats.phases.merge(&cleared.phases);
            stats
        } else if options.distribution == Distribution::Columns {
            if view.is_band() {
                // Nested in a band of its own (the `bands` wrapper): the strips copy in the
                // band's columns; beside it the frame is blocked as every band's frame is.
                let raster = self.direct_raster.as_mut().unwrap_or(&mut self.workers[0].raster);
                let (c, r) = (view.columns(), view.rows());
                raster.clear_region(frame, [c.start, r.start, c.end, r.end]);
            }
            let (stats, made) = self.render_columns(frame, recheck, &bands)?;
            setup = made;
            stats
        } else {
            self.render_distributed(view, frame, recheck)?
        };
        crate::check_cancel(&self.workers[0].raster)?;
        if let Some(direct) = &mut self.direct {
            let paid = match self.options.distribution {
                Distribution::Columns => self.columns.paid(bands.len()),
                _ => Payoff::paid_together(self.workers.iter().map(|w| &w.payoff)),
            };
            let t = Instant::now();
            direct.culled(view, frame, start.elapsed().saturating_sub(setup), &mut stats, paid)?;
            stats.phases.add(Phase::Other, t.elapsed());
        }
        stats.total = start.elapsed();
        // Under the columns distribution the phases are the strips' thread times, their culling
        // included (`render_columns`); else what the walk did not time is its culling.
        if bands.is_empty() {
            let p = &stats.phases;
            let accounted =
                p.get(Phase::Clear) + p.get(Phase::Raster) + p.get(Phase::DepthStructure) + p.get(Phase::Other);
            stats.phases.add(Phase::Cull, stats.total.saturating_sub(accounted));
        }
        crate::end_frame(&self.workers[0].raster, stats)
    }

    /// The workers' frames and pyramids (each worker's, under `parallel=columns` or `on`; the
    /// first's pyramid otherwise), the direct frames' rasterizer and screening pyramid.
    fn prepare(&mut self, width: u32, height: u32) -> Result<()> {
        match self.options.distribution {
            Distribution::Off => {
                let w = &mut self.workers[0];
                crate::prepare_raster(&mut w.raster, &self.scene, width, height);
                ready_pyramid(&mut w.pyramid, width, height)?;
            }
            _ => {
                for w in &mut self.workers {
                    w.ready(width, height)?;
                }
            }
        }
        if let Some(direct) = &mut self.direct {
            let raster = self.direct_raster.as_mut().unwrap_or(&mut self.workers[0].raster);
            direct.prepare(raster, width, height)?;
        }
        Ok(())
    }

    fn memory_bytes(&self) -> usize {
        self.octrees
            .iter()
            .flatten()
            .map(HybridOctree::memory_bytes)
            .sum::<usize>()
            + self
                .per_node
                .meshlets
                .iter()
                .flatten()
                .map(RunClusters::memory_bytes)
                .sum::<usize>()
            + self.workers.iter().map(Worker::memory_bytes).sum::<usize>()
            + self.direct.as_ref().map_or(0, DirectFrames::memory_bytes)
            + self.direct_raster.as_ref().map_or(0, Rasterizer::memory_bytes)
            + self
                .columns
                .memory_bytes(|s| s.visible.capacity() * std::mem::size_of::<VisEntry>())
    }
}
#[cfg(test)]
impl crate::direct::tests::ForceDirect for Hzb {
    fn force(&mut self, n: u32, abandon: bool) {
        let direct = self.direct.as_mut().expect("payoff is on by default");
        direct.force(n, abandon);
        for w in &mut self.workers {
            w.payoff.force_stop = abandon;
        }
        for s in self.columns.strips_mut() {
            s.payoff.force_stop = abandon;
        }
    }

    fn direct(&self) -> &DirectFrames {
        self.direct.as_ref().expect("payoff is on by default")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn build(p: Params) -> Result<HzbOptions> {
        HzbOptions::from_params(&p)
    }

    #[test]
    fn workers_default_to_the_rasterizers_threads() {
        for spec in [Params::new("hzb"), Params::new("hzb").with("workers", "Threads")] {
            assert_eq!(
                build(spec).expect("workers=threads is valid").workers,
                0,
                "resolved when the renderer is built"
            );
        }
        assert_eq!(
            build(Params::new("hzb").with("workers", "3"))
                .expect("3 workers are valid")
                .workers,
            3
        );
        for v in ["0", "9", "all"] {
            let e = build(Params::new("hzb").with("workers", v)).unwrap_err().to_string();
            assert!(e.contains("threads") && e.contains(v), "{e}");
        }
        let scene = Arc::new(crate::test_quad_rows(2, 2));
        for threads in [1, 3] {
            let options = RenderOptions {
                raster: occult_raster::RasterConfig {
                    threads,
                    ..Default::default()
                },
                ..Default::default()
            };
            let hzb = HzbOptions {
                distribution: Distribution::Columns,
                ..HzbOptions::default()
            };
            let h = Hzb::new(scene.clone(), &options, &hzb).expect("hzb builds on a small scene");
            assert_eq!(h.workers.len(), threads);
        }
        let too_many = HzbOptions {
            workers: MAX_WORKERS + 1,
            ..HzbOptions::default()
        };
        assert!(Hzb::new(scene, &RenderOptions::default(), &too_many).is_err());
    }

    #[test]
    fn auto_distribution_takes_columns_on_large_scenes_drawn_on_several_threads() {
        let (small, large) = (crate::test_quad_rows(2, 4096), crate::test_quad_rows(1024, 4096));
        assert!(small.item_count() < AUTO_COLUMNS && large.item_count() >= AUTO_COLUMNS);
        assert_eq!(
            build(Params::new("hzb")).expect("the defaults are valid").distribution,
            Distribution::Auto
        );
        assert_eq!(Distribution::Auto.resolve(&large, 2), Distribution::Columns);
        assert_eq!(Distribution::Auto.resolve(&large, 1), Distribution::Off);
        assert_eq!(Distribution::Auto.resolve(&small, 2), Distribution::Off);
        for d in [Distribution::Off, Distribution::Columns, Distribution::Hybrid] {
            assert_eq!(d.resolve(&large, 2), d, "an explicit distribution stays");
        }
    }

    #[test]
    fn bad_parameters_are_named_errors() {
        for (k, v) in [
            ("leaf", "0"),
            ("depth", "0"),
            ("depth", "33"),
            ("recheck", "-1"),
            ("recheck", "0"),
            ("small", "-0.1"),
            ("small", "1.5"),
            ("small", "nan"),
            ("whole", "1.5"),
            ("whole", "-0.5"),
            ("batch", "0"),
            ("leaf", "many"),
            ("temporal", "maybe"),
            ("order", "random"),
        ] {
            match build(Params::new("hzb").with(k, v)) {
                Err(RenderError::BadParameter(m)) => assert!(m.contains(k) && m.contains("hzb"), "{m}"),
                other => panic!("{k}={v}: {other:?}"),
            }
        }
        let o = build(
            Params::new("hzb")
                .with("recheck", "30")
                .with("order", "count")
                .with("temporal", "off"),
        )
        .expect("recheck, order and temporal in range build");
        assert_eq!(o.recheck_every, 30);
        assert_eq!(o.order, ChildOrder::Count);
        assert!(!o.temporal);
    }
}
