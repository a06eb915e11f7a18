//! Progressive occlusion culling with depth queries over uniform and nested grids.
//!
//! # References
//! Hillesland, Salomon, Lastra, Manocha, "Fast and Simple Occlusion Culling using
//! Hardware-Based Depth Queries", 2002 (`papers/occlusion-queries-hillesland-2002.txt`):
//! - §3.1 uniform grid: every triangle assigned to every cell it intersects (exact tri–box
//!   test, [`occult_spatial::grid`]); cells traversed front to back; each cell's box queried
//!   against the current depth before its triangles are drawn; a per-frame stamp so that a
//!   triangle shared by several cells is drawn once ([`OqGridOptions::stamps`]).
//! - §3.2 nested grid: cells with more than a split threshold of triangles subdivided by a
//!   branching factor per axis, to a maximum depth; a visible cell with a subgrid is traversed
//!   recursively ([`GridKind::Nested`]; defaults from §4.1: branching 4, threshold 10,000).
//! - §3.3 traversal in slabs roughly orthogonal to the view direction; all visible geometry of
//!   slab *i* is drawn before slab *i + 1* is queried ([`Order::Slabs`]).
//! - §3.4 batched queries: the next *n* cells of a slab are queried together against the same
//!   depth state, then the visible ones are drawn ([`OqGridOptions::batch`]). The queries of a
//!   batch run in parallel on the rasterizer's threads.
//! - §4.1 the triangle threshold below which a cell is drawn without a query
//!   ([`OqGridOptions::query_threshold`]; the paper used 1, i.e. every cell is queried) and
//!   the grid resolution in cells along the longest axis, user-set or automatic
//!   ([`Resolution::Auto`], ~100 elements per cell, which is ~50 cells on the paper's model).
//! - §4.2 "with and without queries": `queries=off` keeps the grid traversal and frustum test
//!   and draws every cell in the frustum, the paper's throughput baseline.
//!
//! # Additions (options; `test=query,nodes=off,whole=0,flush=1,coherence=off,payoff=off` is the
//! paper's algorithm)
//! - Cheap test first ([`CellTest::Pyramid`], `test=pyramid`, the default): a max-depth pyramid
//!   of the frame being drawn ([`occult_raster::ZPyramid`]) is asked about the query's screen
//!   rectangle against the same nearest depth; the span-scanning query runs only where the
//!   pyramid does not find it hidden ([`query_cell`]). The pyramid is brought up to date after
//!   each draw over the screen rectangles of the drawn cells' boxes (of the whole mesh for a
//!   whole draw); a triangle's pixels outside its cell's box are left to the cells they cross,
//!   and a pyramid that misses drawn pixels is only stale there, which is conservative. Answers
//!   are exactly those of the query alone; what changes is their cost (most hidden cells are
//!   found by a few pyramid samples instead of a scan of their silhouette).
//! - Node queries ([`OqGridOptions::node_queries`], `nodes=on`): each node occurrence's box is
//!   queried before its grid is traversed, so a hidden building, tree or instanced unit costs
//!   one query instead of one per top-level cell.
//! - Whole draws ([`OqGridOptions::whole_percent`], `whole=50`): a mesh occurrence whose grid
//!   traversal in an earlier frame drew at least that share of its triangles is drawn whole
//!   (one `DrawTriangles::All` draw, each vertex transformed once, no grid, no stamps) after
//!   its node query, its grid traversed again every [`WHOLE_PROBE_PERIOD`]th frame. This is
//!   frame-to-frame coherence (§6 names it as future work), measured per occurrence: where the
//!   queries cull little of a mesh (a forest's trees, a city seen from above), per-cell lists
//!   and queries cost more than they save, and the renderer falls back to drawing as `zbuffer`
//!   does.
//! - Visible list ([`OqGridOptions::coherence`], `coherence=on`): the leaf cells of mesh grids
//!   found visible in the last queried frame (and the meshes drawn whole) are drawn first, as
//!   one draw the rasterizer shares over its threads, without queries; the pyramid is brought up
//!   to date over them; then the grids are traversed as usual, and a visible cell drawn first is
//!   not drawn again. The depth the queries see is then almost complete from the start, so
//!   cells that only looked visible because their occluders came later in the traversal are
//!   culled (on `plant`'s orbit, 1.56 M of 2.28 M triangles drawn per frame without the list,
//!   0.24 M with it). The frame records its own list for the next (cells found visible, drawn
//!   first or not); a cell no longer visible drops out of it. A frame drawn directly records no
//!   list and drops the one it finds: the next queried frame's view is no longer the list's.
//!   Frame-to-frame coherence is the paper's §6 future work; the list is hzb's §3.3 visible
//!   list at cell granularity. Counters `coherent_cells`, `coherent_triangles`.
//! - Weighed list ([`OqGridOptions::weigh`], `weigh=on`): the list is drawn first only while
//!   the last frame that drew it was faster than the last that did not (the first frame, which
//!   has none, is one), the way not taken measured again after 16, 32, 64 frames
//!   ([`crate::list_choice`], as `hzb` and `clusters` weigh theirs); each strip of
//!   `parallel=columns` chooses for itself. A frame that skips the list still records one (its
//!   queries' verdicts); the frame that draws such a list, made against a depth without one,
//!   is not weighed (as `hzb` and `clusters` do). Where the view turns far between frames the list draws what is hidden
//!   now: on the 8-step orbit of `city:blocks=32` it put 14 M triangles a frame into the draws
//!   against 12.5 M without, and frames took 19 % longer; on `plant`'s 32-step orbit it is what
//!   lets the queries cull.
//! - Gathered draws ([`OqGridOptions::flush_triangles`], `flush=1`): visible triangles may be
//!   gathered over batches (and node occurrences) into one draw of at least that many, which
//!   the rasterizer shares over its threads past its sort-last size; queries meanwhile see a
//!   depth without the gathered triangles and cull less. Drawing after every batch (1) measured
//!   best on the plant, city and forest paths; larger values are there for slower queries or
//!   more threads.
//! - Payoff ([`OqGridOptions::payoff`], `payoff=on`, [`crate::payoff`]): a frame whose queries
//!   cost more than they save stops querying; meshes wholly in view are then drawn whole and
//!   the rest of the grids drawn unqueried, in batches large enough for the rasterizer's
//!   threads, without pyramid updates. Counters `payoff_stopped`, `payoff_untested`. Across
//!   frames ([`crate::direct`]): after a frame that was slower than a measured direct frame
//!   (`frustum`'s way, per triangle in view), runs of frames are drawn directly (counter
//!   `payoff_direct`), querying probed between them; a frame headed for more than a direct
//!   frame's time is given up: it stops querying the same way, keeping what it drew.
//! - Strips of columns ([`OqGridOptions::parallel`], `parallel=columns`, [`crate::columns`]):
//!   a queried frame's walk is serial and its draws too small to share over the rasterizer's
//!   threads, so on two cores it runs on one while a direct frame runs on both. Under
//!   `columns` the screen is cut into `strips` strips of columns a worker (a worker a
//!   rasterizer thread), each queried and drawn by a worker as a view restricted to its
//!   columns, against its own depth of them, with its own visible list, shares and payoff; the
//!   frame-level choice stays the renderer's, its direct frames drawn whole on all threads, and
//!   it weighs a queried frame at its cost of a triangle in wall time (the workers' raster time
//!   over their count). `auto`, the default, takes `columns` on scenes of at least
//!   [`crate::columns::AUTO_COLUMNS`] triangle instances drawn on two threads or more.
//!
//! # Instanced scenes
//! The scene DAG is not flattened. A grid is built per *unique* node, in the node's own space:
//! a mesh node's grid holds triangle indices, a group node's grid holds instance indices
//! (assigned by their placed bounds). A frame walks the DAG with the crate's scene walk
//! ([`crate::walk`]: item ids and transforms the same as `zbuffer`'s; the node's box tested but
//! not counted as a box test, the queries being this renderer's box tests); at each
//! node occurrence it traverses that node's grid with the cells placed by `clip_from_object`.
//! A visible cell of a group grid visits its instances (each once per occurrence of the group,
//! by stamp) nearest first (the nearest point of each placed box to the eye), recursing into
//! their grids: a cell holds the near and the far of a street, and an instance entered before
//! its occluders are drawn passes its queries and is drawn. Memory is the sum over unique nodes: linear in the
//! unique triangles and stored instances, whatever the number of triangle instances. Stamps are
//! per unique node too: an epoch is drawn per node *occurrence* (a node is never re-entered
//! while its own occurrence is being traversed, as the DAG has no cycles).
//!
//! # Deviations from the paper
//! - Deviation: the occlusion query is a software depth query on our rasterizer's frame, not a
//!   GPU occlusion query: [`occult_raster::query_box`]'s test in an early-out, span-scanning
//!   form (`query.rs`, an "any samples passed" query). A hardware query's cost is mostly latency
//!   and fill; ours is the pixels scanned until the first passing one.
//! - Deviation: "in flight" means evaluated in parallel (rayon) against the same depth state,
//!   when the batch's queries cover at least [`PARALLEL_QUERY_MIN_PIXELS`] (below that, handing
//!   them to other threads cost more than the queries, measured) and the walk's rasterizer has
//!   more than one thread (a worker of `parallel=columns` has one); there is no pipeline to keep
//!   full, but the culling lost to a batch (cells of a batch do not see each other's geometry)
//!   is the same as in §3.4.
//! - A batch's visible triangles are one draw (or gathered with later ones, `flush`); the
//!   rasterizer draws it on the calling thread unless it is long enough to share over its
//!   threads (by bands of rows, or sort-last when large). Frames do not depend on it.
//! - Deviation: cells are queried with their *tight* box (cell ∩ bounds of its contents), never
//!   larger than the cube of the paper, so at least as much is culled.
//! - Deviation: slabs are bands of the cell centres' distance along the view direction, one
//!   cell extent (along that direction) thick, rather than rasterized planes through the grid
//!   index space; both order cells approximately front to back by planes orthogonal to the view.
//! - Deviation: a grid per unique DAG node (see above) instead of one world grid, so that
//!   instanced scenes stay instanced; occlusion between instances is still found because group
//!   grids are traversed front to back and a cell's instances recursed into nearest first.
//! - Deviation: a level never has more cells than elements
//!   ([`occult_spatial::grid::GridConfig::cells_per_element`] 1), so the resolution applies in
//!   full to large meshes and small groups get small grids.
//!
//! Cost per frame: the non-empty cells of every grid visited (frustum test each), one query per
//! node occurrence and per cell in the frustum with at least `threshold` triangles (most hidden
//! ones answered by a few pyramid samples, plus a pyramid update per draw over the drawn
//! cells' rectangles), plus rasterizing the cells found visible. It pays when the depth
//! complexity is high; with little occlusion the queries are overhead (§1), which whole draws
//! bound: meshes mostly visible are drawn as `zbuffer` draws them. Triangles drawn from
//! per-cell lists cost more each than a whole mesh's (their corners are transformed per
//! triangle), and a batch's draw is usually below the size the rasterizer shares over its
//! threads.

mod query;
mod walk;

use walk::{Depth, Grids, Temporal};

pub use query::{any_sample_passes, query_cell, QueryOutcome};

use std::sync::Arc;
use std::time::{Duration, Instant};

use occult_core::{Mat4, NodeId, NodeKind, Scene, View};
use occult_raster::{Frame, Rasterizer, ZPyramid};
pub use occult_spatial::grid::Resolution;
use occult_spatial::grid::{GridConfig, GridError, MeshTriangles, NestedGrid, WeightedBoxes};

use crate::columns::{Columns, StripWorker, MAX_STRIPS, MAX_WORKERS};
use crate::direct::DirectFrames;
use crate::params::read_params;
use crate::payoff::Payoff;
use crate::walk::Placed;
use crate::{AlgorithmInfo, FrameStats, ParamDoc, Params, Phase, RenderError, RenderOptions, Renderer, Result};

/// Registry entry: every [`OqGridOptions`] field is a parameter.
pub static INFO: AlgorithmInfo = AlgorithmInfo {
    name: "oqgrid",
    summary: "progressive occlusion culling with depth queries over uniform/nested grids, front-to-back slabs, batched queries (Hillesland et al. 2002)",
    params: &[
        ParamDoc {
            key: "grid",
            default: "nested",
            help: "uniform (one level per node, §3.1) or nested (full cells split, §3.2)",
        },
        ParamDoc {
            key: "resolution",
            default: "auto",
            help: "cells along the longest axis of each node's grid (>= 1), or auto (~100 elements per cell)",
        },
        ParamDoc {
            key: "branching",
            default: "4",
            help: "nested: subcells per axis of a split cell (>= 2)",
        },
        ParamDoc {
            key: "split",
            default: "10000",
            help: "nested: cells with more triangles than this are split (>= 1)",
        },
        ParamDoc {
            key: "depth",
            default: "3",
            help: "nested: most levels below the top (0..=16)",
        },
        ParamDoc {
            key: "batch",
            default: "4",
            help: "queries in flight: a slab's next n cells queried together, in parallel (>= 1)",
        },
        ParamDoc {
            key: "threshold",
            default: "1",
            help: "cells with fewer triangles are drawn without a query (>= 1; 1 queries every cell)",
        },
        ParamDoc {
            key: "test",
            default: "pyramid",
            help: "query: the span-scanning query only (the paper's); pyramid: a max-depth pyramid of the current depth first, the query where it is inconclusive",
        },
        ParamDoc {
            key: "flush",
            default: "1",
            help: "visible triangles gathered before they are drawn (>= 1; 1 draws after every batch, as the paper)",
        },
        ParamDoc {
            key: "nodes",
            default: "on",
            help: "query each node occurrence's box before traversing its grid (off: only cells are queried, as the paper)",
        },
        ParamDoc {
            key: "whole",
            default: "50",
            help: "percent (0..=100, 0: never): a mesh occurrence whose grid traversal in an earlier frame drew at least this share of its triangles is drawn whole (box queried, vertices shared, no grid), its grid traversed again every 8th frame",
        },
        ParamDoc {
            key: "queries",
            default: "on",
            help: "off: draw every cell in the frustum (grid frustum culling only, the §4.2 baseline)",
        },
        ParamDoc {
            key: "order",
            default: "slabs",
            help: "slabs (front to back, §3.3) or none (storage order)",
        },
        ParamDoc {
            key: "stamps",
            default: "on",
            help: "draw a triangle shared by several visible cells once per frame (§3.1)",
        },
        ParamDoc {
            key: "memory",
            default: "4096",
            help: "bound on all grids, MiB, checked before allocating (>= 1)",
        },
        ParamDoc {
            key: "coherence",
            default: "on",
            help: "draw the cells (and whole meshes) found visible last frame first, unqueried, then traverse the grids as usual, skipping what is drawn (frame-to-frame coherence, the paper's §6 future work; with queries=off there is nothing to skip and it does nothing)",
        },
        ParamDoc {
            key: "weigh",
            default: "on",
            help: "draw last frame's visible cells first only while frames that drew them were faster than frames that did not (the last of each; the other way measured again after 16, 32, 64 frames; each strip of parallel=columns chooses for itself); off = whenever coherence is on; needs coherence (not in the paper)",
        },
        ParamDoc {
            key: "payoff",
            default: "on",
            help: "stop querying for the rest of a frame once queries cost more than they save, and draw the rest directly; draw runs of frames as frustum does while queried frames are slower than such direct frames (not in the paper)",
        },
        ParamDoc {
            key: "parallel",
            default: "auto",
            help: "off: one walk, parallelism the rasterizer's own; columns: each of the rasterizer's threads (at most 8) queries and draws strips of the screen's columns with its own depth (not in the paper); auto: columns on scenes of at least 8,000,000 triangle instances drawn on 2 threads or more, else off",
        },
        ParamDoc {
            key: "strips",
            default: "2",
            help: "parallel=columns: strips of columns a worker, 1..=16, handed out one at a time to whichever worker is free",
        },
    ],
    counters: &DECLARED,
    conservative: true,
    bands: true,
    build: |scene, options, params| {
        Ok(Box::new(OqGrid::with_options(scene, options, &OqGridOptions::from_params(params)?)?))
    },
};

/// The counters of [`OqGridCounts`] (in the order of [`OqGridCounts::values`]), then the
/// payoff's, the frame-level choice's and the columns distribution's.
const COUNTERS: [&str; 20] = [
    "cells_visited",
    "cells_in_frustum",
    "queries",
    "queries_hidden",
    "queries_skipped",
    "cells_visible",
    "node_occurrences",
    "parallel_batches",
    "pyramid_hidden",
    "draws",
    "node_queries",
    "nodes_hidden",
    "whole_drawn",
    "coherent_cells",
    "coherent_triangles",
    crate::payoff::COUNTERS[0],
    crate::payoff::COUNTERS[1],
    crate::direct::COUNTER,
    crate::direct::SCREENED,
    crate::columns::STRIPS,
];

/// Every counter a frame may report: [`COUNTERS`], then the workers' busy and idle times.
const DECLARED: [&str; COUNTERS.len() + 2 * MAX_WORKERS] = crate::columns::declared(&COUNTERS);

/// Uniform (§3.1) or nested (§3.2) grids.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridKind {
    /// One level per node.
    Uniform,
    /// Cells over the split threshold subdivided, to the maximum depth.
    Nested,
}

/// How a cell's occlusion query is answered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellTest {
    /// The span-scanning query alone ([`any_sample_passes`]), the paper's one query.
    Query,
    /// A max-depth pyramid of the current depth first, the query only where the pyramid does
    /// not find the cell hidden ([`query_cell`]).
    Pyramid,
}

/// Whether culled frames are drawn as strips of columns ([`crate::columns`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Parallel {
    /// One walk; parallelism is the rasterizer's own.
    Off,
    /// Each worker (one a rasterizer thread, at most [`MAX_WORKERS`]) queries and draws strips
    /// of the screen's columns, each against its own depth of them.
    Columns,
    /// [`Parallel::Columns`] on a scene of at least [`crate::columns::AUTO_COLUMNS`] triangle
    /// instances drawn on two threads or more, else [`Parallel::Off`]; chosen when the renderer
    /// is built.
    Auto,
}

impl Parallel {
    /// [`Parallel::Auto`] resolved for `scene` drawn on `threads` threads; others as they are.
    pub fn resolve(self, scene: &Scene, threads: usize) -> Self {
        match self {
            Self::Auto if crate::columns::auto_takes_columns(scene, threads) => Self::Columns,
            Self::Auto => Self::Off,
            p => p,
        }
    }
}

/// Order in which a grid's cells are queried.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Order {
    /// §3.3: slabs orthogonal to the view direction, front to back.
    Slabs,
    /// Storage order (for measuring what the ordering buys; still conservative).
    Unordered,
}

/// Tunables of [`OqGrid`].
#[derive(Clone, Debug, PartialEq)]
pub struct OqGridOptions {
    /// Uniform or nested grids.
    pub grid: GridKind,
    /// Cells along the longest axis of each node's top-level grid.
    pub resolution: Resolution,
    /// Subcells per axis of a split cell (nested only; ≥ 2).
    pub branching: u32,
    /// Cells with more elements than this are split (nested only; ≥ 1).
    pub split_threshold: usize,
    /// Most levels below the top (nested only).
    pub max_depth: u32,
    /// Queries in flight per batch (§3.4; ≥ 1).
    pub batch: usize,
    /// Cells with fewer triangles than this are drawn without a query (§4.1; ≥ 1, 1 queries
    /// every cell).
    pub query_threshold: u64,
    /// Query cells at all (`false`: frustum culling over the grid only, §4.2's baseline).
    pub queries: bool,
    /// How a query is answered.
    pub test: CellTest,
    /// Visible triangles gathered before they are drawn (≥ 1; 1 draws after every batch). More
    /// makes fewer, larger draws (which the rasterizer shares over its threads past a size)
    /// but queries meanwhile see a depth without the gathered triangles, so cull less.
    pub flush_triangles: usize,
    /// Percent (0..=100; 0: never): a mesh occurrence whose grid traversal in an earlier frame
    /// drew at least this share of its triangles is drawn whole (every triangle, its vertices
    /// transformed once; its box queried with [`OqGridOptions::node_queries`]) instead of
    /// traversing its grid, which is traversed again every [`WHOLE_PROBE_PERIOD`]th frame to
    /// measure the share anew (frame-to-frame coherence, the paper's §6 future work). Where
    /// queries cull little of a mesh, they and the per-triangle lists cost more than drawing it
    /// all.
    pub whole_percent: u32,
    /// Query each node occurrence's box before its grid (with [`OqGridOptions::queries`]).
    pub node_queries: bool,
    /// Cell order.
    pub order: Order,
    /// Draw a triangle shared by several visible cells once (§3.1), or once per cell.
    pub stamps: bool,
    /// Draw last frame's visible cells and whole meshes first, unqueried, then traverse the
    /// grids as usual without drawing them again (frame-to-frame coherence, §6's future work).
    pub coherence: bool,
    /// With [`OqGridOptions::coherence`], draw the list first only while the last frame that
    /// drew it was faster than the last that did not ([`crate::list_choice`]).
    pub weigh: bool,
    /// Stop querying for the rest of a frame once the queries cost more than they save, and
    /// draw the rest directly ([`crate::payoff`]); draw whole frames directly while queried
    /// frames are slower than direct ones ([`crate::direct`]). Not in the paper.
    pub payoff: bool,
    /// Bound on all grids' bytes, checked before allocating.
    pub max_memory_bytes: usize,
    /// Culled frames as strips of columns (not in the paper).
    pub parallel: Parallel,
    /// Under [`Parallel::Columns`], strips of columns a worker (1 ..= [`MAX_STRIPS`]).
    pub strips: usize,
}

impl Default for OqGridOptions {
    fn default() -> Self {
        Self {
            grid: GridKind::Nested,
            resolution: Resolution::Auto,
            branching: 4,
            split_threshold: 10_000,
            max_depth: 3,
            batch: 4,
            query_threshold: 1,
            queries: true,
            test: CellTest::Pyramid,
            flush_triangles: 1,
            whole_percent: 50,
            node_queries: true,
            order: Order::Slabs,
            stamps: true,
            coherence: true,
            weigh: true,
            payoff: true,
            max_memory_bytes: 4 << 30,
            parallel: Parallel::Auto,
            strips: 2,
        }
    }
}

impl OqGridOptions {
    /// The options set by `params` (absent keys keep their defaults), validated.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] naming the key and value.
    pub fn from_params(params: &Params) -> Result<Self> {
        let d = Self::default();
        let resolution = match params.raw("resolution").map(str::trim) {
            None => d.resolution,
            Some(v) if v.eq_ignore_ascii_case("auto") => Resolution::Auto,
            Some(v) => Resolution::Cells(v.parse().map_err(|_| {
                RenderError::BadParameter(format!("oqgrid: resolution={v}: expected auto or a number of cells"))
            })?),
        };
        let memory_mib: usize = params.get("memory", d.max_memory_bytes >> 20)?;
        if memory_mib == 0 || memory_mib > (1 << 30) {
            return Err(RenderError::BadParameter(format!(
                "oqgrid: memory={memory_mib}: expected 1..=1073741824 MiB"
            )));
        }
        let mut o = Self {
            grid: match params.choice("grid", &["uniform", "nested"], "nested")? {
                "uniform" => GridKind::Uniform,
                _ => GridKind::Nested,
            },
            resolution,
            max_memory_bytes: memory_mib << 20,
            ..d
        };
        read_params!(params, o, {
            branching: "branching",
            split_threshold: "split",
            max_depth: "depth",
            batch: "batch",
            query_threshold: "threshold",
            flush_triangles: "flush",
            whole_percent: "whole",
            node_queries: flag "nodes",
            queries: flag "queries",
        });
        o.test = match params.choice("test", &["query", "pyramid"], "pyramid")? {
            "query" => CellTest::Query,
            _ => CellTest::Pyramid,
        };
        o.order = match params.choice("order", &["slabs", "none"], "slabs")? {
            "none" => Order::Unordered,
            _ => Order::Slabs,
        };
        read_params!(params, o, { stamps: flag "stamps", coherence: flag "coherence", weigh: flag "weigh", payoff: flag "payoff", strips: "strips" });
        o.parallel = match params.choice("parallel", &["auto", "off", "columns"], "auto")? {
            "off" => Parallel::Off,
            "columns" => Parallel::Columns,
            _ => Parallel::Auto,
        };
        o.validate()?;
        Ok(o)
    }

    /// Checks the ranges.
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] naming the value.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(RenderError::BadParameter(format!("oqgrid: {m}")));
        if self.resolution == Resolution::Cells(0) {
            return bad("resolution=0: a grid needs at least 1 cell along its longest axis".into());
        }
        if let Resolution::Cells(n) = self.resolution {
            if n as u64 > occult_spatial::grid::MAX_AXIS_CELLS {
                return bad(format!(
                    "resolution={n}: at most {} cells along an axis",
                    occult_spatial::grid::MAX_AXIS_CELLS
                ));
            }
        }
        if self.branching < 2 {
            return bad(format!("branching={}: must be at least 2", self.branching));
        }
        if self.split_threshold == 0 {
            return bad("split=0: the split threshold must be at least 1".into());
        }
        if self.batch == 0 {
            return bad("batch=0: at least 1 query must be in flight".into());
        }
        if self.whole_percent > 100 {
            return bad(format!("whole={}: a percentage, 0..=100", self.whole_percent));
        }
        if self.flush_triangles == 0 {
            return bad("flush=0: must be at least 1 (1 draws after every batch)".into());
        }
        if self.query_threshold == 0 {
            return bad("threshold=0: must be at least 1 (1 queries every cell)".into());
        }
        if !(1..=MAX_STRIPS).contains(&self.strips) {
            return bad(format!(
                "strips={}: strips a worker must be in 1..={MAX_STRIPS}",
                self.strips
            ));
        }
        if self.max_depth > 16 {
            return bad(format!("depth={}: at most 16 nested levels", self.max_depth));
        }
        Ok(())
    }

    fn grid_config(&self, max_bytes: usize) -> GridConfig {
        GridConfig {
            resolution: self.resolution,
            branching: self.branching,
            split_threshold: self.split_threshold,
            max_depth: match self.grid {
                GridKind::Uniform => 0,
                GridKind::Nested => self.max_depth,
            },
            max_bytes,
            cells_per_element: 1.0,
        }
    }
}

/// The occlusion-query grid renderer.
pub struct OqGrid {
    scene: Arc<Scene>,
    /// On all threads: the walk's under `parallel=off`, and direct frames'.
    raster: Rasterizer,
    options: OqGridOptions,
    /// Per node of the scene: its grid, in the node's space.
    grids: Vec<NestedGrid>,
    /// The walk's pyramid and stamps under `parallel=off`.
    depth: Depth,
    /// What the frames keep from frame to frame under `parallel=off`.
    temporal: Temporal,
    last_counts: OqGridCounts,
    /// What the queries' balance learned from earlier frames ([`crate::payoff`]), under
    /// `parallel=off`.
    payoff: Payoff,
    /// Frames drawn directly where querying does not pay (`payoff=on`).
    direct: Option<DirectFrames>,
    /// The workers of `parallel=columns` (none under `off`).
    workers: Vec<Worker>,
    /// The strips of `parallel=columns`, each with its own temporal state and payoff.
    columns: Columns<Temporal>,
    /// The last frame was drawn directly: the visible lists are of an older view.
    lists_stale: bool,
}

/// A worker of `parallel=columns`: a one-thread rasterizer, its frame, pyramid and stamps.
struct Worker {
    raster: Rasterizer,
    frame: Option<Frame>,
    depth: Depth,
    /// Its walks query through a pyramid ([`CellTest::Pyramid`]), made with its frame.
    pyramid: bool,
}

impl StripWorker for Worker {
    fn raster(&mut self) -> &mut Rasterizer {
        &mut self.raster
    }

    fn ready(&mut self, width: u32, height: u32) -> Result<bool> {
        if matches!(&self.frame, Some(f) if f.width() == width && f.height() == height) {
            return Ok(false);
        }
        self.frame = None;
        self.frame = Some(Frame::new(width, height)?);
        if self.pyramid {
            self.depth.pyramid = ZPyramid::default();
            self.depth.pyramid = ZPyramid::new(width, height)?;
        }
        Ok(true)
    }

    fn frame(&self) -> &Frame {
        match &self.frame {
            Some(f) => f,
            None => unreachable!("made by `ready` before a strip is drawn"),
        }
    }
}

/// The visible leaf cells of mesh occurrences found in one frame, grouped by occurrence
/// ([`OqGridOptions::coherence`]).
#[derive(Default)]
struct VisibleCells {
    /// Each occurrence and its range of `cells`.
    occurrences: Vec<(Placed, usize, usize)>,
    /// Cell keys ([`cell_key`]), or [`WHOLE`] for an occurrence drawn whole.
    cells: Vec<u64>,
}

impl VisibleCells {
    fn clear(&mut self) {
        self.occurrences.clear();
        self.cells.clear();
    }

    fn memory_bytes(&self) -> usize {
        self.occurrences.capacity() * std::mem::size_of::<(Placed, usize, usize)>() + self.cells.capacity() * 8
    }
}

/// The key of cell `cell` of grid level `level` in [`VisibleCells`].
fn cell_key(level: u32, cell: u32) -> u64 {
    (u64::from(level) << 32) | u64::from(cell)
}

/// The key of a mesh occurrence drawn whole in [`VisibleCells`].
const WHOLE: u64 = u64::MAX;

/// Most cells a visible list remembers; past it the frame's list stops growing (the next frame
/// draws less first, nothing else changes).
const MAX_VISIBLE_CELLS: usize = 1 << 21;

impl OqGrid {
    /// Builds the grids of `scene` (one per unique node).
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] for out-of-range options, or grids that would exceed the
    /// memory bound (refused before allocating); raster configuration errors.
    pub fn with_options(scene: Arc<Scene>, options: &RenderOptions, oq: &OqGridOptions) -> Result<Self> {
        oq.validate()?;
        let raster = crate::scene_rasterizer(&scene, options)?;
        let mut left = oq.max_memory_bytes;
        let mut grids = Vec::with_capacity(scene.nodes().len());
        let mut stamps = Vec::with_capacity(scene.nodes().len());
        for node in scene.nodes() {
            let config = oq.grid_config(left);
            let built = raster.install(|| match node.kind() {
                NodeKind::Mesh(m) => NestedGrid::build(&MeshTriangles(m), m.bounds(), &config),
                NodeKind::Group(g) => {
                    let boxes = WeightedBoxes {
                        boxes: g
                            .iter()
                            .map(|i| scene.node(i.child).bounds().transformed(&i.parent_from_child))
                            .collect(),
                        weights: g.iter().map(|i| scene.node(i.child).item_count()).collect(),
                    };
                    NestedGrid::build(&boxes, node.bounds(), &config)
                }
            });
            let grid = built.map_err(|e| match e {
                GridError::BadConfig(m) => RenderError::BadParameter(format!("oqgrid: {m}")),
                e @ GridError::TooLarge { .. } => RenderError::BadParameter(format!(
                    "oqgrid: resolution={}: grid of node '{}' refused: {e}",
                    match oq.resolution {
                        Resolution::Auto => "auto".to_string(),
                        Resolution::Cells(n) => n.to_string(),
                    },
                    node.name()
                )),
            })?;
            left = left.saturating_sub(grid.memory_bytes());
            let elements = match node.kind() {
                NodeKind::Mesh(m) => m.triangle_count(),
                NodeKind::Group(g) => g.len(),
            };
            grids.push(grid);
            stamps.push(vec![0u32; if oq.stamps { elements } else { 0 }]);
        }
        let mut settings = oq.clone();
        settings.parallel = settings.parallel.resolve(&scene, raster.thread_count());
        let (workers, strips) = match settings.parallel {
            Parallel::Columns => {
                let one = occult_raster::RasterConfig {
                    threads: 1,
                    ..options.raster.clone()
                };
                let n = raster.thread_count().clamp(1, MAX_WORKERS);
                let workers = (0..n)
                    .map(|_| {
                        Ok(Worker {
                            raster: Rasterizer::new(one.clone())?,
                            frame: None,
                            depth: Depth {
                                pyramid: ZPyramid::default(),
                                stamps: stamps.clone(),
                                epoch: 0,
                            },
                            pyramid: settings.test == CellTest::Pyramid,
                        })
                    })
                    .collect::<Result<Vec<_>>>()?;
                (workers, n * settings.strips)
            }
            _ => (Vec::new(), 0),
        };
        let columns = Columns::new(strips, || {
            (Temporal::default(), Payoff::new(oq.payoff, scene.item_count()))
        });
        Ok(Self {
            payoff: Payoff::new(oq.payoff, scene.item_count()),
            direct: match oq.payoff {
                true => Some(
                    DirectFrames::new(scene.clone(), &raster)?
                        .judging_first_by_time()
                        .culled_on(workers.len()),
                ),
                false => None,
            },
            scene,
            raster,
            options: settings,
            grids,
            depth: Depth {
                pyramid: ZPyramid::default(),
                // The workers' own under `parallel=columns`.
                stamps: if workers.is_empty() { stamps } else { Vec::new() },
                epoch: 0,
            },
            temporal: Temporal::default(),
            last_counts: OqGridCounts::default(),
            workers,
            columns,
            lists_stale: false,
        })
    }

    /// The options it was built with.
    pub fn options(&self) -> &OqGridOptions {
        &self.options
    }

    /// The counts of the last frame rendered.
    pub fn last_counts(&self) -> OqGridCounts {
        self.last_counts
    }

    /// The grid of node `id`.
    pub fn grid(&self, id: NodeId) -> &NestedGrid {
        &self.grids[id.index()]
    }
}

/// A mesh occurrence drawn whole (see [`OqGridOptions::whole_percent`]) has its grid traversed
/// again every this many frames, to measure the share it draws anew.
pub const WHOLE_PROBE_PERIOD: u32 = 8;

/// Most mesh occurrences whose drawn share is remembered; past it, all are forgotten at once.
const MAX_REMEMBERED_SHARES: usize = 1 << 20;

/// Screen pixels below which a batch's queries are evaluated on the calling thread.
pub const PARALLEL_QUERY_MIN_PIXELS: f32 = 131_072.0;

/// Area in pixels of the screen rectangle of `aabb`'s corners (the whole screen when a corner
/// is behind the eye): an estimate of a query's work.
fn screen_area_estimate(clip_from_object: &Mat4, aabb: &occult_core::Aabb, w: f32, h: f32) -> f32 {
    let (mut x0, mut x1, mut y0, mut y1) = (f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY);
    for c in aabb.corners() {
        let p = *clip_from_object * c.extend(1.0);
        if p.w.is_nan() || p.w <= 0.0 {
            return w * h;
        }
        let (x, y) = (p.x / p.w, p.y / p.w);
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let dx = (x1.min(1.0) - x0.max(-1.0)).max(0.0) * 0.5 * w;
    let dy = (y1.min(1.0) - y0.max(-1.0)).max(0.0) * 0.5 * h;
    dx * dy
}

/// Counts of one frame (also reported as named counters).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OqGridCounts {
    /// Non-empty cells visited (frustum-tested).
    pub cells_visited: u64,
    /// Cells inside the frustum.
    pub cells_in_frustum: u64,
    /// Occlusion queries issued.
    pub queries: u64,
    /// Queries that found the cell hidden.
    pub queries_hidden: u64,
    /// Cells in the frustum drawn without a query because they hold fewer triangles than the
    /// threshold.
    pub queries_skipped: u64,
    /// Cells found visible (by query, or drawn unqueried).
    pub cells_visible: u64,
    /// Node occurrences entered (DAG nodes in the frustum).
    pub node_occurrences: u64,
    /// Batches whose queries were evaluated in parallel.
    pub parallel_batches: u64,
    /// Queries (of cells and nodes) answered "hidden" by the pyramid alone, without scanning
    /// pixels.
    pub pyramid_hidden: u64,
    /// Draws handed to the rasterizer.
    pub draws: u64,
    /// Node occurrences queried by their box before their grid (not counted in `queries`).
    pub node_queries: u64,
    /// Node occurrences found hidden by that query (not counted in `queries_hidden`).
    pub nodes_hidden: u64,
    /// Mesh occurrences drawn whole (see [`OqGridOptions::whole_percent`]).
    pub whole_drawn: u64,
    /// Cells (and whole meshes) of last frame's visible list drawn first, unqueried
    /// ([`OqGridOptions::coherence`]).
    pub coherent_cells: u64,
    /// Triangles they held.
    pub coherent_triangles: u64,
}

impl OqGridCounts {
    /// Adds `other`'s counts (another strip's of the same frame).
    fn add(&mut self, other: &Self) {
        let mut sum = self.values();
        for (s, o) in sum.iter_mut().zip(other.values()) {
            *s += o;
        }
        let [cells_visited, cells_in_frustum, queries, queries_hidden, queries_skipped, cells_visible, node_occurrences, parallel_batches, pyramid_hidden, draws, node_queries, nodes_hidden, whole_drawn, coherent_cells, coherent_triangles] =
            sum;
        *self = Self {
            cells_visited,
            cells_in_frustum,
            queries,
            queries_hidden,
            queries_skipped,
            cells_visible,
            node_occurrences,
            parallel_batches,
            pyramid_hidden,
            draws,
            node_queries,
            nodes_hidden,
            whole_drawn,
            coherent_cells,
            coherent_triangles,
        };
    }

    /// The counts in the order of [`INFO`]'s counter names.
    fn values(&self) -> [u64; 15] {
        [
            self.cells_visited,
            self.cells_in_frustum,
            self.queries,
            self.queries_hidden,
            self.queries_skipped,
            self.cells_visible,
            self.node_occurrences,
            self.parallel_batches,
            self.pyramid_hidden,
            self.draws,
            self.node_queries,
            self.nodes_hidden,
            self.whole_drawn,
            self.coherent_cells,
            self.coherent_triangles,
        ]
    }
}

impl Renderer for OqGrid {
    fn name(&self) -> &'static str {
        "oqgrid"
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        crate::check_frame(view, frame)?;
        let bands = match self.options.parallel {
            Parallel::Columns => self.columns.views(view, "oqgrid")?,
            _ => Vec::new(),
        };
        if let Some(direct) = &mut self.direct {
            let drawn = direct.render_if_due(&mut self.raster, view, frame);
            if !matches!(drawn, Ok(None)) {
                // Drawn directly, or begun so and cancelled.
                self.lists_stale = true;
            }
            if let Some(stats) = drawn? {
                return crate::end_frame(&self.raster, stats);
            }
            if bands.is_empty() {
                direct.arm(&mut self.payoff, self.raster.thread_count());
            } else {
                self.columns.arm(direct, view, &bands, self.workers.len());
            }
        }
        if std::mem::take(&mut self.lists_stale) {
            // Frame-to-frame coherence is between consecutive frames: a list recorded before a
            // run of direct frames is of a view since left (on an orbit of eight steps, 90° away
            // after one direct frame), and drawn first it is mostly hidden now.
            self.temporal.visible.clear();
            for s in self.columns.strips_mut() {
                s.state.visible.clear();
            }
        }
        let start = Instant::now();
        let grids = Grids {
            scene: &self.scene,
            grids: &self.grids,
            options: &self.options,
            strips: bands.len().max(1),
        };
        let (mut stats, counts, setup) = if bands.is_empty() {
            let (stats, counts) = grids.walk_frame(
                view,
                &mut self.raster,
                frame,
                &mut self.depth,
                &mut self.temporal,
                &mut self.payoff,
            )?;
            (stats, counts, Duration::ZERO)
        } else {
            if view.is_band() {
                // Nested in a band of its own (the `bands` wrapper): the strips copy in the
                // band's columns; beside it the frame is blocked as every band's frame is.
                let (c, r) = (view.columns(), view.rows());
                self.raster.clear_region(frame, [c.start, r.start, c.end, r.end]);
            }
            let counts = std::sync::Mutex::new(OqGridCounts::default());
            let workers = self.workers.iter_mut().collect();
            let (stats, setup) = self
                .columns
                .render(workers, frame, &bands, &[], |w: &mut Worker, strip, band| {
                    let Some(f) = w.frame.as_mut() else {
                        unreachable!("made by `ready`");
                    };
                    let (stats, c) = grids.walk_frame(
                        band,
                        &mut w.raster,
                        f,
                        &mut w.depth,
                        &mut strip.state,
                        &mut strip.payoff,
                    )?;
                    counts.lock().unwrap_or_else(std::sync::PoisonError::into_inner).add(&c);
                    Ok(stats)
                })?;
            let counts = counts.into_inner().unwrap_or_else(std::sync::PoisonError::into_inner);
            (stats, counts, setup)
        };
        if let Some(direct) = &mut self.direct {
            let paid = match bands.is_empty() {
                true => self.payoff.last_paid(),
                false => self.columns.paid(bands.len()),
            };
            let t = Instant::now();
            direct.culled(view, frame, start.elapsed().saturating_sub(setup), &mut stats, paid)?;
            stats.phases.add(Phase::Other, t.elapsed());
        }
        stats.total = start.elapsed();
        self.last_counts = counts;
        crate::end_frame(&self.raster, stats)
    }

    /// Under `parallel=columns`, the workers' frames and pyramids; else the rasterizer's
    /// private frames and the pyramid of `test=pyramid`. The direct frames' rasterizer and
    /// screening pyramid.
    fn prepare(&mut self, width: u32, height: u32) -> Result<()> {
        if self.workers.is_empty() {
            crate::prepare_raster(&mut self.raster, &self.scene, width, height);
            let pyramid = &self.depth.pyramid;
            if self.options.test == CellTest::Pyramid && (pyramid.width(), pyramid.height()) != (width, height) {
                self.depth.pyramid = ZPyramid::new(width, height)?;
            }
        }
        for w in &mut self.workers {
            w.ready(width, height)?;
        }
        if let Some(direct) = &mut self.direct {
            direct.prepare(&mut self.raster, width, height)?;
        }
        Ok(())
    }

    fn memory_bytes(&self) -> usize {
        self.grids.iter().map(NestedGrid::memory_bytes).sum::<usize>()
            + self.depth.memory_bytes()
            + self.temporal.memory_bytes()
            + self.raster.memory_bytes()
            + self.direct.as_ref().map_or(0, DirectFrames::memory_bytes)
            + self
                .workers
                .iter()
                .map(|w| {
                    w.depth.memory_bytes() + w.raster.memory_bytes() + w.frame.as_ref().map_or(0, Frame::memory_bytes)
                })
                .sum::<usize>()
            + self.columns.memory_bytes(Temporal::memory_bytes)
    }
}

#[cfg(test)]
impl crate::direct::tests::ForceDirect for OqGrid {
    fn force(&mut self, n: u32, abandon: bool) {
        let direct = self.direct.as_mut().expect("payoff is on by default");
        direct.force(n, abandon);
        self.payoff.force_stop = abandon;
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

    #[test]
    fn auto_takes_columns_on_large_scenes_drawn_on_several_threads() {
        let (small, large) = (crate::test_quad_rows(2, 4096), crate::test_quad_rows(1024, 4096));
        let auto = OqGridOptions::from_params(&Params::new("oqgrid")).expect("the defaults are valid");
        assert_eq!(auto.parallel, Parallel::Auto);
        assert_eq!(Parallel::Auto.resolve(&large, 2), Parallel::Columns);
        assert_eq!(Parallel::Auto.resolve(&large, 1), Parallel::Off);
        assert_eq!(Parallel::Auto.resolve(&small, 2), Parallel::Off);
        for p in [Parallel::Off, Parallel::Columns] {
            assert_eq!(p.resolve(&large, 2), p, "an explicit choice stays");
        }
        let columns = Params::new("oqgrid").with("parallel", "columns").with("strips", "3");
        let o = OqGridOptions::from_params(&columns).expect("valid");
        assert_eq!((o.parallel, o.strips), (Parallel::Columns, 3));
    }

    /// Each count is reported under its own name: the registry's first names follow the
    /// order of [`OqGridCounts::values`].
    #[test]
    fn counts_are_reported_by_their_names() {
        let names = [
            "cells_visited",
            "cells_in_frustum",
            "queries",
            "queries_hidden",
            "queries_skipped",
            "cells_visible",
            "node_occurrences",
            "parallel_batches",
            "pyramid_hidden",
            "draws",
            "node_queries",
            "nodes_hidden",
            "whole_drawn",
            "coherent_cells",
            "coherent_triangles",
        ];
        let counts = OqGridCounts {
            cells_visited: 1,
            cells_in_frustum: 2,
            queries: 3,
            queries_hidden: 4,
            queries_skipped: 5,
            cells_visible: 6,
            node_occurrences: 7,
            parallel_batches: 8,
            pyramid_hidden: 9,
            draws: 10,
            node_queries: 11,
            nodes_hidden: 12,
            whole_drawn: 13,
            coherent_cells: 14,
            coherent_triangles: 15,
        };
        assert_eq!(counts.values(), std::array::from_fn(|i| i as u64 + 1));
        assert_eq!(&INFO.counters[..names.len()], &names[..]);
        let mut twice = counts;
        twice.add(&counts);
        assert_eq!(twice.values(), std::array::from_fn(|i| 2 * (i as u64 + 1)));
    }

    /// A cell of a group's grid enters its instances nearest first, whatever their order in
    /// the group: a row of boxes along the view, stored farthest first in one cell, draws the
    /// nearest box and the ground only (the boxes behind are queried hidden).
    #[test]
    fn a_cell_enters_its_instances_nearest_first() {
        use occult_core::Vec3;
        let scene = crate::tests::cubes_on_ground(
            [-9.0, 9.0, -20.0, 2.0],
            (0..9).rev().map(|i| Vec3::new(0.0, 0.0, -2.0 * i as f32)),
        );
        let mut reference = Frame::new(96, 64).expect("frame");
        let eye = Vec3::new(0.0, 0.0, 4.0);
        let view = View::new(occult_core::Camera::look_at(eye, Vec3::new(0.0, 0.0, -4.0)), 96, 64).expect("a view");
        crate::zbuffer::ZBuffer::new(scene.clone(), &RenderOptions::default())
            .expect("zbuffer builds")
            .render(&view, &mut reference)
            .expect("zbuffer renders");
        let o = OqGridOptions {
            resolution: Resolution::Cells(1),
            payoff: false,
            ..Default::default()
        };
        let mut r = OqGrid::with_options(scene, &RenderOptions::default(), &o).expect("builds");
        let mut frame = Frame::new(96, 64).expect("frame");
        let stats = r.render(&view, &mut frame).expect("renders");
        assert!(frame.same_visibility(&reference));
        // The ground's 2 triangles and the nearest box's 12.
        assert_eq!(
            stats.triangles_submitted, 14,
            "the boxes behind the first are not drawn"
        );
    }

    /// `weigh=on`: a visible list whose frames were slower than frames without it is not drawn
    /// first (the traversal draws the frame alone, the same frame); `weigh=off` draws it
    /// whatever the times.
    #[test]
    fn weighing_skips_a_list_that_cost_time() {
        use occult_core::Vec3;
        let scene = crate::tests::cubes_on_ground(
            [-9.0, 9.0, -20.0, 2.0],
            (0..4).map(|i| Vec3::new(0.0, 0.0, -3.0 * i as f32)),
        );
        let view = View::new(
            occult_core::Camera::look_at(Vec3::new(1.0, 2.0, 6.0), Vec3::new(0.0, 0.0, -4.0)),
            96,
            64,
        )
        .expect("a view");
        let mut reference = Frame::new(96, 64).expect("frame");
        crate::zbuffer::ZBuffer::new(scene.clone(), &RenderOptions::default())
            .expect("zbuffer builds")
            .render(&view, &mut reference)
            .expect("zbuffer renders");
        for weigh in [true, false] {
            let o = OqGridOptions {
                payoff: false,
                weigh,
                ..Default::default()
            };
            let mut r = OqGrid::with_options(scene.clone(), &RenderOptions::default(), &o).expect("builds");
            let mut frame = Frame::new(96, 64).expect("frame");
            let first = r.render(&view, &mut frame).expect("renders");
            assert_eq!(first.counters.get("coherent_cells"), 0, "the first frame has no list");
            assert!(
                !r.temporal.visible.cells.is_empty(),
                "the first frame lists its visible cells"
            );
            // A frame with the list that took a second: the list costs time.
            r.temporal.choice.record(true, std::time::Duration::from_secs(1));
            let second = r.render(&view, &mut frame).expect("renders");
            assert!(frame.same_visibility(&reference));
            assert_eq!(
                second.counters.get("coherent_cells") > 0,
                !weigh,
                "weigh={weigh}: the list is drawn first only when not weighed"
            );
        }
    }

    /// Under `parallel=columns` a frame is drawn as strips of columns by a worker a thread, its
    /// counts those of the strips together.
    #[test]
    fn columns_draw_strips_on_every_thread() {
        let scene = Arc::new(crate::test_quad_rows(8, 8));
        let options = RenderOptions {
            raster: occult_raster::RasterConfig {
                threads: 2,
                ..Default::default()
            },
            ..Default::default()
        };
        let o = OqGridOptions {
            parallel: Parallel::Columns,
            strips: 3,
            payoff: false,
            ..Default::default()
        };
        let mut r = OqGrid::with_options(scene, &options, &o).expect("builds");
        assert_eq!(r.workers.len(), 2);
        let eye = occult_core::Vec3::new(4.0, 4.0, 12.0);
        let camera = occult_core::Camera::look_at(eye, occult_core::Vec3::new(4.0, 4.0, 0.0));
        let view = View::new(camera, 160, 96).expect("a view");
        let mut frame = Frame::new(160, 96).expect("frame");
        let stats = r.render(&view, &mut frame).expect("renders");
        assert_eq!(stats.counters.get(crate::columns::STRIPS), 6);
        assert_eq!(r.last_counts().queries, stats.counters.get("queries"));
        assert!(r.last_counts().queries > 0);
    }
}
