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
//!   first or not); a cell no longer visible drops out of it. Frame-to-frame coherence is the
//!   paper's §6 future work; the list is hzb's §3.3 visible list at cell granularity. Counters
//!   `coherent_cells`, `coherent_triangles`.
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
//!
//! # Instanced scenes
//! The scene DAG is not flattened. A grid is built per *unique* node, in the node's own space:
//! a mesh node's grid holds triangle indices, a group node's grid holds instance indices
//! (assigned by their placed bounds). A frame walks the DAG with the crate's scene walk
//! ([`crate::walk`]: item ids and transforms the same as `zbuffer`'s; the node's box tested but
//! not counted as a box test, the queries being this renderer's box tests); at each
//! node occurrence it traverses that node's grid with the cells placed by `clip_from_object`.
//! A visible cell of a group grid visits its instances (each once per occurrence of the group,
//! by stamp), recursing into their grids. Memory is the sum over unique nodes: linear in the
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
//!   them to other threads cost more than the queries, measured); there is no pipeline to keep
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
//!   grids are traversed front to back and their instances recursed into in that order.
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

pub use query::{any_sample_passes, query_cell, QueryOutcome};

use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::time::{Duration, Instant};

use occult_core::{Containment, Mat4, Mesh, NodeId, NodeKind, Scene, Vec3, View};
use occult_raster::{Draw, DrawTriangles, Frame, PixelRect, Rasterizer, ZPyramid};
pub use occult_spatial::grid::Resolution;
use occult_spatial::grid::{GridCell, GridConfig, GridError, MeshTriangles, NestedGrid, WeightedBoxes, NO_CHILD};

use crate::direct::DirectFrames;
use crate::hash::FxBuild;
use crate::params::read_params;
use crate::payoff::{FramePayoff, Payoff, DIRECT_BATCH};
use crate::walk::{NodeAt, NodeTest, Placed, SceneWalk, Visitor};
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
            key: "payoff",
            default: "on",
            help: "stop querying for the rest of a frame once queries cost more than they save, and draw the rest directly; draw runs of frames as frustum does while queried frames are slower than such direct frames (not in the paper)",
        },
    ],
    counters: &[
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
    ],
    conservative: true,
    bands: true,
    build: |scene, options, params| {
        Ok(Box::new(OqGrid::with_options(scene, options, &OqGridOptions::from_params(params)?)?))
    },
};

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
    /// Stop querying for the rest of a frame once the queries cost more than they save, and
    /// draw the rest directly ([`crate::payoff`]); draw whole frames directly while queried
    /// frames are slower than direct ones ([`crate::direct`]). Not in the paper.
    pub payoff: bool,
    /// Bound on all grids' bytes, checked before allocating.
    pub max_memory_bytes: usize,
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
            payoff: true,
            max_memory_bytes: 4 << 30,
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
        read_params!(params, o, { stamps: flag "stamps", coherence: flag "coherence", payoff: flag "payoff" });
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
    raster: Rasterizer,
    options: OqGridOptions,
    /// Per node of the scene: its grid, in the node's space.
    grids: Vec<NestedGrid>,
    /// Max-depth pyramid of the frame being drawn ([`CellTest::Pyramid`]).
    pyramid: ZPyramid,
    /// Per node: the epoch at which each element (triangle or instance) was last drawn.
    stamps: Vec<Vec<u32>>,
    epoch: u32,
    /// Per mesh occurrence (by its first item id, unique to it): the share of its triangles the
    /// last traversal of its grid drew, and the frames it was drawn whole since.
    shares: HashMap<u64, (f32, u32), FxBuild>,
    last_counts: OqGridCounts,
    /// What the queries' balance learned from earlier frames ([`crate::payoff`]).
    payoff: Payoff,
    /// Frames drawn directly where querying does not pay (`payoff=on`).
    direct: Option<DirectFrames>,
    /// The last queried frame's visible cells, drawn first by the next ([`OqGridOptions::coherence`]).
    visible: VisibleCells,
    /// The list being recorded by the frame in progress.
    next_visible: VisibleCells,
    /// The cells the frame in progress drew first: (first item of the occurrence, cell key).
    predrawn: HashSet<(u64, u64), FxBuild>,
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
        Ok(Self {
            payoff: Payoff::new(oq.payoff, scene.item_count()),
            direct: match oq.payoff {
                true => Some(DirectFrames::new(scene.clone(), &raster)?.judging_first_by_time()),
                false => None,
            },
            scene,
            raster,
            options: oq.clone(),
            grids,
            pyramid: ZPyramid::default(),
            shares: HashMap::default(),
            stamps,
            epoch: 0,
            last_counts: OqGridCounts::default(),
            visible: VisibleCells::default(),
            next_visible: VisibleCells::default(),
            predrawn: HashSet::default(),
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

/// A node occurrence being traversed.
struct Occurrence<'a> {
    at: NodeAt<'a>,
    clip_from_object: Mat4,
    /// The camera in the node's space, for slab keys.
    eye: Vec3,
    dir: Vec3,
    epoch: u32,
    grid: &'a NestedGrid,
}

/// Visible triangles of one mesh occurrence gathered for the next draw.
struct Pending<'a> {
    mesh: &'a Mesh,
    /// Its triangle indices: `Walk::gathered[start..end]`; None: all of them.
    gathered: Option<(usize, usize)>,
    clip_from_object: Mat4,
    first_item: u64,
}

/// Per-frame traversal state.
struct Walk<'a> {
    walk: SceneWalk<'a>,
    grids: &'a [NestedGrid],
    stamps: &'a mut [Vec<u32>],
    epoch: &'a mut u32,
    shares: &'a mut HashMap<u64, (f32, u32), FxBuild>,
    /// Triangles gathered for drawing so far in the frame.
    gathered_count: u64,
    raster: &'a mut Rasterizer,
    options: &'a OqGridOptions,
    frame: &'a mut Frame,
    counts: OqGridCounts,
    query_time: Duration,
    raster_time: Duration,
    /// Time spent bringing the pyramid up to date.
    pyramid_time: Duration,
    /// The pyramid of `frame` ([`CellTest::Pyramid`]), up to date but for the `dirty` rectangles.
    pyramid: Option<&'a mut ZPyramid>,
    /// Triangle indices of the pending draws.
    gathered: Vec<u32>,
    pending: Vec<Pending<'a>>,
    /// Triangles of the pending draws.
    pending_triangles: usize,
    /// Where the pending draws may change the depth.
    dirty: Vec<PixelRect>,
    /// Whether the queries still pay this frame.
    payoff: FramePayoff,
    /// Records this frame's visible cells, when coherence is on.
    record: Option<&'a mut VisibleCells>,
    /// The cells drawn first this frame (keys as in [`OqGrid::predrawn`]).
    predrawn: HashSet<(u64, u64), FxBuild>,
}

impl<'a> Visitor<'a> for Walk<'a> {
    /// The node's box is tested but not counted: this renderer's box tests are its queries.
    const NODE_TEST: NodeTest = NodeTest::Uncounted;

    fn walk(&mut self) -> &mut SceneWalk<'a> {
        &mut self.walk
    }

    /// Traverses the occurrence's grid from its top level.
    fn visit(&mut self, at: &NodeAt<'a>) {
        self.counts.node_occurrences += 1;
        self.next_epoch();
        let view = self.walk.view();
        let clip_from_object = view.clip_from_object(&at.place.world_from_node);
        if self.options.queries && self.options.node_queries && !self.node_visible(at, &clip_from_object) {
            return;
        }
        if let NodeKind::Mesh(_) = at.node.kind() {
            if self.predrawn.contains(&(at.place.first_item, WHOLE)) {
                // Drawn whole first, from last frame's list: visible still (its box passed).
                if let Some((_, since)) = self.shares.get_mut(&at.place.first_item) {
                    *since += 1;
                }
                self.counts.whole_drawn += 1;
                self.remember(at.place, &[WHOLE]);
                return;
            }
        }
        if let (NodeKind::Mesh(mesh), true) = (at.node.kind(), self.payoff.stopped() && at.inside) {
            // Queries stopped paying: a mesh occurrence wholly in view is drawn whole.
            self.push_whole(mesh, at, clip_from_object);
            self.remember(at.place, &[WHOLE]);
            return;
        }
        let whole = self.options.whole_percent;
        if let (NodeKind::Mesh(mesh), true) = (at.node.kind(), whole > 0) {
            if let Some((share, since)) = self.shares.get_mut(&at.place.first_item) {
                if *share * 100.0 >= whole as f32 && *since + 1 < WHOLE_PROBE_PERIOD {
                    *since += 1;
                    self.counts.whole_drawn += 1;
                    self.push_whole(mesh, at, clip_from_object);
                    self.remember(at.place, &[WHOLE]);
                    return;
                }
            }
        }
        let gathered_before = self.gathered_count;
        // A mesh's cells are recorded by `batch` while its grid is traversed (a group's
        // instances record their own).
        let recorded_before = match at.node.kind() {
            NodeKind::Mesh(_) => self.record.as_ref().map(|r| r.cells.len()),
            NodeKind::Group(_) => None,
        };
        let node_from_world = at.place.world_from_node.inverse();
        let camera = view.camera();
        let occ = Occurrence {
            at: *at,
            clip_from_object,
            eye: node_from_world.transform_point3(camera.eye),
            dir: node_from_world.transform_vector3(camera.direction()),
            epoch: *self.epoch,
            grid: &self.grids[at.place.id.index()],
        };
        self.level(&occ, 0);
        if let (Some(record), Some(start)) = (self.record.as_deref_mut(), recorded_before) {
            if record.cells.len() > start {
                record.occurrences.push((at.place, start, record.cells.len()));
            }
        }
        if let (NodeKind::Mesh(mesh), true) = (at.node.kind(), whole > 0) {
            let drawn = (self.gathered_count - gathered_before) as f32;
            if self.shares.len() >= MAX_REMEMBERED_SHARES {
                self.shares.clear(); // bounded memory on scenes of countless occurrences
            }
            self.shares
                .insert(at.place.first_item, (drawn / mesh.triangle_count().max(1) as f32, 0));
        }
    }
}

impl<'a> Walk<'a> {
    /// Traverses level `level_index` of the occurrence's grid: §3.3 slabs, §3.4 batches.
    fn level(&mut self, occ: &Occurrence<'a>, level_index: u32) {
        let level = &occ.grid.levels()[level_index as usize];
        let thickness = occ.dir.abs().dot(level.cell_size);
        let thickness = if thickness.is_finite() && thickness > 0.0 {
            thickness
        } else {
            1.0
        };
        let mut order: Vec<(i64, u32)> = Vec::with_capacity(level.cells.len());
        for (i, cell) in level.cells.iter().enumerate() {
            self.counts.cells_visited += 1;
            if occ.at.frustum.classify_aabb(&cell.tight) == Containment::Outside {
                continue;
            }
            let key = match self.options.order {
                // §3.3: the slab of the cell's centre along the view direction.
                Order::Slabs => ((cell.tight.center() - occ.eye).dot(occ.dir) / thickness).floor() as i64,
                Order::Unordered => 0,
            };
            order.push((key, i as u32));
        }
        self.counts.cells_in_frustum += order.len() as u64;
        if self.options.order == Order::Slabs {
            order.sort_unstable();
        }
        let mut start = 0;
        while start < order.len() {
            let slab = order[start].0;
            let end = start + order[start..].iter().take_while(|(k, _)| *k == slab).count();
            // §3.4: the slab's cells n at a time; each batch drawn before the next is queried,
            // and the whole slab before the next slab.
            for batch in order[start..end].chunks(self.options.batch) {
                self.batch(occ, level_index, batch);
            }
            start = end;
        }
    }

    /// Queries the cells of one batch against the same depth state, then draws the visible
    /// ones (§3.4) and recurses into the visible ones' subgrids (§3.2) and instances.
    fn batch(&mut self, occ: &Occurrence<'a>, level_index: u32, batch: &[(i64, u32)]) {
        if self.raster.config().control.is_cancelled() {
            return; // the frame is not drawn at all
        }
        let cells: &'a [GridCell] = &occ.grid.levels()[level_index as usize].cells;
        let options = self.options;
        let wants_query = |c: &GridCell| options.queries && c.weight >= options.query_threshold;
        // One balance check for the batch: its queries run together.
        let wanted = batch.iter().filter(|(_, i)| wants_query(&cells[*i as usize])).count() as u64;
        let testing = wanted == 0 || self.payoff.test();
        if !testing {
            self.payoff.skipped(wanted.saturating_sub(1));
        }
        let needs_query = |c: &GridCell| testing && wants_query(c);
        let view = self.walk.view();
        let t = Instant::now();
        let pyramid = self.pyramid.as_deref();
        let query = |c: &GridCell| -> QueryOutcome {
            if needs_query(c) {
                query_cell(self.frame, view, &occ.clip_from_object, &c.tight, pyramid)
            } else {
                QueryOutcome::Visible
            }
        };
        let queried = batch.iter().filter(|(_, i)| needs_query(&cells[*i as usize])).count() as u64;
        // Deviation (§3.4): a batch's queries run in parallel only when their screen area makes
        // it pay; small queries cost less than handing them to other threads.
        let parallel = queried > 1 && {
            let (w, h) = (view.width() as f32, view.height() as f32);
            let area: f32 = batch
                .iter()
                .filter(|(_, i)| needs_query(&cells[*i as usize]))
                .map(|(_, i)| screen_area_estimate(&occ.clip_from_object, &cells[*i as usize].tight, w, h))
                .sum();
            area >= PARALLEL_QUERY_MIN_PIXELS
        };
        let outcomes: Vec<QueryOutcome> = if parallel {
            use rayon::prelude::*;
            self.counts.parallel_batches += 1;
            self.raster
                .install(|| batch.par_iter().map(|(_, i)| query(&cells[*i as usize])).collect())
        } else {
            batch.iter().map(|(_, i)| query(&cells[*i as usize])).collect()
        };
        if queried > 0 {
            self.query_time += t.elapsed();
        }
        self.counts.pyramid_hidden += outcomes.iter().filter(|&&o| o == QueryOutcome::HiddenByPyramid).count() as u64;
        let visible: Vec<bool> = outcomes.iter().map(|&o| o == QueryOutcome::Visible).collect();
        let visible_count = visible.iter().filter(|&&v| v).count() as u64;
        let hidden = batch
            .iter()
            .zip(&visible)
            .filter(|((_, i), v)| !**v && needs_query(&cells[*i as usize]))
            .count() as u64;
        self.counts.queries += queried;
        self.counts.queries_hidden += hidden;
        let saved: u64 = batch
            .iter()
            .zip(&visible)
            .filter(|(_, v)| !**v)
            .map(|((_, i), _)| cells[*i as usize].weight)
            .sum();
        self.payoff.saved(saved);
        self.counts.queries_skipped += batch.len() as u64 - queried;
        self.counts.cells_visible += visible_count;
        if visible_count == 0 {
            return;
        }
        let elements = occ.grid.elements();
        match occ.at.node.kind() {
            NodeKind::Mesh(mesh) => {
                // The visible leaf cells' triangles, each once per occurrence (§3.1 stamps).
                let start = self.gathered.len();
                let (w, h) = (view.width(), view.height());
                for (&(_, i), _) in batch.iter().zip(&visible).filter(|(_, v)| **v) {
                    let cell = &cells[i as usize];
                    if cell.child != NO_CHILD {
                        continue;
                    }
                    let key = cell_key(level_index, i);
                    if let Some(record) = self.record.as_deref_mut() {
                        if record.cells.len() < MAX_VISIBLE_CELLS {
                            record.cells.push(key);
                        }
                    }
                    if !self.predrawn.is_empty() && self.predrawn.contains(&(occ.at.place.first_item, key)) {
                        continue; // drawn first, from last frame's list
                    }
                    let tris = &elements[cell.range()];
                    if options.stamps {
                        let stamps = &mut self.stamps[occ.at.place.id.index()];
                        for &t in tris {
                            if stamps[t as usize] != occ.epoch {
                                stamps[t as usize] = occ.epoch;
                                self.gathered.push(t);
                            }
                        }
                    } else {
                        self.gathered.extend_from_slice(tris);
                    }
                    // The pyramid is brought up to date over the cell's own box only: the parts of
                    // its triangles outside it are left to the cells they cross (a pyramid that
                    // misses pixels drawn is stale there, which is conservative).
                    if self.pyramid.is_some() {
                        if let Some(r) = query::screen_rect(&occ.clip_from_object, &cell.tight, w, h) {
                            self.dirty.push(r);
                        }
                    }
                }
                if self.gathered.len() > start {
                    self.pending_triangles += self.gathered.len() - start;
                    self.gathered_count += (self.gathered.len() - start) as u64;
                    self.pending.push(Pending {
                        mesh,
                        gathered: Some((start, self.gathered.len())),
                        clip_from_object: occ.clip_from_object,
                        first_item: occ.at.place.first_item,
                    });
                    if self.pending_triangles >= self.flush_at() {
                        self.flush();
                    }
                }
                for (&(_, i), _) in batch.iter().zip(&visible).filter(|(_, v)| **v) {
                    let child = cells[i as usize].child;
                    if child != NO_CHILD {
                        self.level(occ, child);
                    }
                }
            }
            NodeKind::Group(_) => {
                for (&(_, i), _) in batch.iter().zip(&visible).filter(|(_, v)| **v) {
                    let cell = &cells[i as usize];
                    if cell.child != NO_CHILD {
                        self.level(occ, cell.child);
                        continue;
                    }
                    for &e in &elements[cell.range()] {
                        if options.stamps {
                            let s = &mut self.stamps[occ.at.place.id.index()][e as usize];
                            if *s == occ.epoch {
                                continue;
                            }
                            *s = occ.epoch;
                        }
                        self.enter(occ.at.child(e as usize), false);
                    }
                }
            }
        }
    }
}

impl<'a> Walk<'a> {
    /// A fresh stamp epoch for the next occurrence.
    fn next_epoch(&mut self) {
        *self.epoch = self.epoch.wrapping_add(1);
        if *self.epoch == 0 {
            // After 2^32 occurrences: forget every stamp once, so old epochs cannot match.
            self.stamps.iter_mut().for_each(|s| s.fill(0));
            *self.epoch = 1;
        }
    }

    /// Records cells `keys` of mesh occurrence `place` in this frame's visible list.
    fn remember(&mut self, place: Placed, keys: &[u64]) {
        if let Some(record) = self.record.as_deref_mut() {
            if record.cells.len() + keys.len() <= MAX_VISIBLE_CELLS {
                let start = record.cells.len();
                record.cells.extend_from_slice(keys);
                record.occurrences.push((place, start, record.cells.len()));
            }
        }
    }

    /// Draws last frame's visible list first, unqueried (frame-to-frame coherence): each
    /// remembered mesh occurrence in view, whole or its remembered cells in view, as one draw
    /// (shared over the rasterizer's threads when large), then the pyramid brought up to date
    /// over them. Their keys go to `predrawn`, so the traversal does not draw them again.
    fn predraw(&mut self, last: &VisibleCells) {
        let view = self.walk.view();
        let scene = self.walk.scene();
        let (w, h) = (view.width(), view.height());
        for &(place, start, end) in &last.occurrences {
            let node = scene.node(place.id);
            let NodeKind::Mesh(mesh) = node.kind() else {
                continue;
            };
            let frustum = view.frustum(&place.world_from_node);
            let bounds = node.bounds();
            if bounds.is_empty() || frustum.classify_aabb(&bounds) == Containment::Outside {
                continue;
            }
            let clip_from_object = view.clip_from_object(&place.world_from_node);
            let keys = &last.cells[start..end];
            // Drawn whole when the traversal would draw it whole (`visit`'s rule); not drawn
            // first when its grid is due to be traversed again, to measure its share.
            let whole_percent = self.options.whole_percent as f32;
            let share = self.shares.get(&place.first_item);
            let probe_due = share.is_some_and(|&(_, since)| since + 1 >= WHOLE_PROBE_PERIOD);
            let whole = if keys == [WHOLE] {
                if probe_due {
                    continue;
                }
                true
            } else {
                whole_percent > 0.0 && !probe_due && share.is_some_and(|&(s, _)| s * 100.0 >= whole_percent)
            };
            if whole {
                self.predrawn.insert((place.first_item, WHOLE));
                self.counts.coherent_cells += 1;
                self.counts.coherent_triangles += mesh.triangle_count() as u64;
                self.pend_whole(mesh, &bounds, place.first_item, clip_from_object);
                continue;
            }
            self.next_epoch();
            let epoch = *self.epoch;
            let grid = &self.grids[place.id.index()];
            let elements = grid.elements();
            let first = self.gathered.len();
            for &key in keys {
                let (level, index) = ((key >> 32) as usize, key as u32 as usize);
                let Some(cell) = grid.levels().get(level).and_then(|l| l.cells.get(index)) else {
                    continue;
                };
                if frustum.classify_aabb(&cell.tight) == Containment::Outside {
                    continue;
                }
                self.predrawn.insert((place.first_item, key));
                self.counts.coherent_cells += 1;
                let tris = &elements[cell.range()];
                if self.options.stamps {
                    let stamps = &mut self.stamps[place.id.index()];
                    for &t in tris {
                        if stamps[t as usize] != epoch {
                            stamps[t as usize] = epoch;
                            self.gathered.push(t);
                        }
                    }
                } else {
                    self.gathered.extend_from_slice(tris);
                }
                if self.pyramid.is_some() {
                    if let Some(r) = query::screen_rect(&clip_from_object, &cell.tight, w, h) {
                        self.dirty.push(r);
                    }
                }
            }
            if self.gathered.len() > first {
                let n = self.gathered.len() - first;
                self.counts.coherent_triangles += n as u64;
                self.pending_triangles += n;
                self.pending.push(Pending {
                    mesh,
                    gathered: Some((first, self.gathered.len())),
                    clip_from_object,
                    first_item: place.first_item,
                });
            }
        }
        self.flush();
    }

    /// Queries the box of occurrence `at` before its grid is traversed; false when hidden.
    fn node_visible(&mut self, at: &NodeAt<'a>, clip_from_object: &Mat4) -> bool {
        if !self.payoff.test() {
            return true;
        }
        let t = Instant::now();
        let outcome = query_cell(
            self.frame,
            self.walk.view(),
            clip_from_object,
            &at.node.bounds(),
            self.pyramid.as_deref(),
        );
        self.query_time += t.elapsed();
        self.counts.node_queries += 1;
        if outcome == QueryOutcome::Visible {
            return true;
        }
        self.counts.nodes_hidden += 1;
        self.counts.pyramid_hidden += (outcome == QueryOutcome::HiddenByPyramid) as u64;
        self.payoff.saved(at.node.item_count());
        false
    }

    /// Adds every triangle of mesh occurrence `at` to the pending draws, drawn once enough
    /// are pending.
    fn push_whole(&mut self, mesh: &'a Mesh, at: &NodeAt<'a>, clip_from_object: Mat4) {
        self.pend_whole(mesh, &at.node.bounds(), at.place.first_item, clip_from_object);
        if self.pending_triangles >= self.flush_at() {
            self.flush();
        }
    }

    /// Adds every triangle of the mesh occurrence with box `bounds` and first item `first_item`
    /// to the pending draws (and its screen rectangle to the pyramid's dirty ones).
    fn pend_whole(&mut self, mesh: &'a Mesh, bounds: &occult_core::Aabb, first_item: u64, clip_from_object: Mat4) {
        if self.pyramid.is_some() {
            let (w, h) = (self.frame.width(), self.frame.height());
            if let Some(r) = query::screen_rect(&clip_from_object, bounds, w, h) {
                self.dirty.push(r);
            }
        }
        self.pending_triangles += mesh.triangle_count();
        self.pending.push(Pending {
            mesh,
            gathered: None,
            clip_from_object,
            first_item,
        });
    }

    /// Triangles gathered before a draw: the option's, or large threaded batches once the
    /// frame stopped querying.
    fn flush_at(&self) -> usize {
        if self.payoff.stopped() {
            DIRECT_BATCH.max(self.options.flush_triangles)
        } else {
            self.options.flush_triangles
        }
    }

    /// Draws the pending triangles as one draw list, then brings the pyramid up to date where
    /// they may have changed the depth.
    fn flush(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        let view = self.walk.view();
        let draws: Vec<Draw<'_>> = self
            .pending
            .iter()
            .map(|p| Draw {
                mesh: p.mesh,
                triangles: match p.gathered {
                    Some((start, end)) => DrawTriangles::List(&self.gathered[start..end]),
                    None => DrawTriangles::All,
                },
                clip_from_object: p.clip_from_object,
                first_item: p.first_item,
            })
            .collect();
        let t = Instant::now();
        crate::rasterize(self.raster, view, self.frame, &draws, &mut self.walk.stats);
        drop(draws);
        self.counts.draws += 1;
        let spent = t.elapsed();
        self.raster_time += spent;
        let shared = self.pending_triangles >= DIRECT_BATCH;
        self.payoff.rasterized(self.pending_triangles as u64, spent, shared);
        // Only where the batch wrote: its rectangles cut to the box of the triangles that wrote
        // a fragment (none left when it was wholly hidden).
        match crate::written_region(self.raster, view) {
            Some(w) => {
                self.dirty.retain_mut(|r| match r.intersect(&w) {
                    Some(cut) => {
                        *r = cut;
                        true
                    }
                    None => false,
                });
            }
            None => self.dirty.clear(),
        }
        // Once the frame stopped querying, nothing reads the pyramid.
        let stopped = self.payoff.stopped();
        if let Some(pyramid) = self
            .pyramid
            .as_deref_mut()
            .filter(|_| !self.dirty.is_empty() && !stopped)
        {
            let t = Instant::now();
            // Rectangles overlap: where their bounding rectangle is no larger than their areas
            // together, one pass over it is less work.
            let area: u64 = self.dirty.iter().map(|r| r.area()).sum();
            let union = self.dirty.iter().fold(self.dirty[0], |u, r| PixelRect {
                x0: u.x0.min(r.x0),
                y0: u.y0.min(r.y0),
                x1: u.x1.max(r.x1),
                y1: u.y1.max(r.y1),
            });
            if union.area() <= area {
                pyramid.update(self.frame, union);
            } else {
                for &r in &self.dirty {
                    pyramid.update(self.frame, r);
                }
            }
            self.pyramid_time += t.elapsed();
        }
        self.pending.clear();
        self.pending_triangles = 0;
        self.gathered.clear();
        self.dirty.clear();
    }
}

impl Renderer for OqGrid {
    fn name(&self) -> &'static str {
        "oqgrid"
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        crate::check_frame(view, frame)?;
        if let Some(direct) = &mut self.direct {
            if let Some(stats) = direct.render_if_due(&mut self.raster, view, frame)? {
                return crate::end_frame(&self.raster, stats);
            }
            direct.arm(&mut self.payoff, self.raster.thread_count());
        }
        let (start, t, cleared) = crate::begin_frame(&mut self.raster, view, frame)?;
        let control = self.raster.config().control.clone();
        let pyramid = match self.options.test {
            CellTest::Query => None,
            CellTest::Pyramid => {
                if (self.pyramid.width(), self.pyramid.height()) != (frame.width(), frame.height()) {
                    self.pyramid = ZPyramid::new(frame.width(), frame.height())?;
                }
                self.pyramid.clear_for(frame);
                Some(&mut self.pyramid)
            }
        };
        let mut walk = Walk {
            walk: SceneWalk::new(&self.scene, view),
            grids: &self.grids,
            stamps: &mut self.stamps,
            epoch: &mut self.epoch,
            shares: &mut self.shares,
            gathered_count: 0,
            raster: &mut self.raster,
            options: &self.options,
            frame,
            counts: OqGridCounts::default(),
            query_time: Duration::ZERO,
            raster_time: Duration::ZERO,
            pyramid_time: Duration::ZERO,
            pyramid,
            gathered: Vec::new(),
            pending: Vec::new(),
            pending_triangles: 0,
            dirty: Vec::new(),
            payoff: self.payoff.begin(t),
            record: None,
            predrawn: std::mem::take(&mut self.predrawn),
        };
        walk.walk.stats = cleared;
        walk.predrawn.clear();
        if self.options.coherence && self.options.queries {
            // Last frame's visible list first (its keys in `predrawn`), then the traversal,
            // which records this frame's list.
            walk.predraw(&self.visible);
            self.next_visible.clear();
            walk.record = Some(&mut self.next_visible);
        }
        walk.run();
        walk.flush();
        let walked = t.elapsed();
        let Walk {
            walk,
            counts,
            query_time,
            raster_time,
            pyramid_time,
            payoff,
            predrawn,
            record,
            ..
        } = walk;
        self.predrawn = predrawn;
        let recorded = record.is_some();
        // A cancelled frame's list is incomplete, and its costs are no measure: both dropped.
        if control.is_cancelled() {
            return Err(crate::RenderError::Cancelled);
        }
        self.payoff.end(&payoff);
        let mut stats = walk.finish("oqgrid")?;
        if recorded {
            // This frame's list replaces the last (one that stopped querying, given up or not,
            // lists what it drew untested).
            std::mem::swap(&mut self.visible, &mut self.next_visible);
        }
        stats.phases.add(Phase::Query, query_time);
        stats.phases.add(Phase::DepthStructure, pyramid_time);
        stats.phases.add(
            Phase::Cull,
            walked.saturating_sub(query_time + raster_time + pyramid_time),
        );
        stats.boxes_tested += counts.queries + counts.node_queries;
        stats.boxes_culled += counts.queries_hidden + counts.nodes_hidden;
        // The counters are named in `INFO.counters`, in the order of `OqGridCounts::values`.
        debug_assert_eq!(
            INFO.counters.len(),
            counts.values().len() + crate::payoff::COUNTERS.len() + 2 // and `direct`'s two
        );
        for (&name, n) in INFO.counters.iter().zip(counts.values()) {
            stats.counters.add(name, n);
        }
        stats.counters.add_all(payoff.counters());
        if let Some(direct) = &mut self.direct {
            let t = Instant::now();
            direct.culled(view, frame, start.elapsed(), &mut stats, self.payoff.last_paid())?;
            stats.phases.add(Phase::Other, t.elapsed());
        }
        stats.total = start.elapsed();
        self.last_counts = counts;
        crate::end_frame(&self.raster, stats)
    }

    fn memory_bytes(&self) -> usize {
        self.grids.iter().map(NestedGrid::memory_bytes).sum::<usize>()
            + self.stamps.iter().map(|s| s.len() * 4).sum::<usize>()
            + self.pyramid.memory_bytes()
            + self.shares.capacity() * std::mem::size_of::<(u64, (f32, u32))>()
            + self.raster.memory_bytes()
            + self.direct.as_ref().map_or(0, DirectFrames::memory_bytes)
            + self.visible.memory_bytes()
            + self.next_visible.memory_bytes()
            + self.predrawn.capacity() * 16
    }
}

#[cfg(test)]
impl crate::direct::tests::ForceDirect for OqGrid {
    fn force(&mut self, n: u32, abandon: bool) {
        let direct = self.direct.as_mut().expect("payoff is on by default");
        direct.force(n, abandon);
        self.payoff.force_stop = abandon;
    }

    fn direct(&self) -> &DirectFrames {
        self.direct.as_ref().expect("payoff is on by default")
    }
}
