//! The exact triangle rasterizer: one triangle setup and one scan, driven four ways.
//!
//! - **Direct** (one thread): each triangle is set up and scanned at once, in submission order;
//!   consecutive triangles of a mesh touch neighbouring pixels, so the frame stays in cache.
//! - **Banded** (several threads, shorter draws whose fill is the cost): every thread sets up
//!   every triangle and scans it over its own bands of rows (interleaved bands of 32 rows) of
//!   the frame itself; no private frames, no merge. The caller takes bands too, beside helper
//!   threads of the rasterizer's own that wait for the next draw spinning a while
//!   ([`helpers`]): the culling renderers' batches last a tenth of a millisecond to a few, too
//!   short to wait for a sleeping pool thread.
//! - **Sort-last** (several threads, draws of at least 200,000 triangles): worker `k` of
//!   `threads` (a job any thread of the pool may run) draws the blocks `k, k + threads, …` of
//!   the triangle stream directly into its own frame (worker 0 into the real one); the other
//!   frames are merged under the (depth, item) rule over the pixels each touched.
//! - **Tile-binned** (several threads, when asked for, or when sort-last cannot allocate its
//!   private frames), in rounds of `threads × 2` chunks of [`CHUNK_TRIANGLES`] triangles:
//!   1. *setup and binning* (parallel over chunks): each set-up triangle is appended to the bin
//!      of each tile its box touches;
//!   2. *rasterization* (parallel over tiles): each tile scans the triangles of its bins.
//!
//!   The automatic strategy draws a draw too small for sort-last directly on the calling
//!   thread, or by bands when it is expected to be long: binning it cost more than it saved in
//!   every renderer measured (see `Rasterizer::shared_as`).
//!
//! The calling thread drives every draw (and the stencil pass). On one thread it does all the
//! work itself (the rasterizer's one-thread pool serves only [`Rasterizer::install`]); on
//! several it hands each parallel phase to the pool as jobs that any thread may take (see
//! `Workers::share`) and waits for them.
//!
//! Setup, shared by all four: transform vertices (whole meshes: each vertex once per draw, in
//! parallel; index lists and ranges: per triangle, through a small per-draw cache so that the
//! corners neighbouring triangles share are mostly transformed once, or with AVX2 every corner,
//! eight at a time, which costs less), trivially reject by
//! outcodes, clip the rare triangle that crosses the near plane or the guard band, snap to fixed
//! point, reject empty boxes and zero areas, and fix the depth plane. Where the processor has
//! AVX2, vertices are projected and triangles set up eight at a time, in lanes
//! ([`setup8`]), with the same operations in the same order as the scalar path (tested bit
//! for bit). The scan derives exact integer edge functions (the 8-lane setup hands them over
//! for small boxes) and finds covered pixels with branch-free 8-pixel masks (boxes up to 64
//! pixels) or per-row integer span solving (larger ones: a reciprocal's estimate moved to the
//! exact bound, no division per row); with AVX2 a span's fragments are depth-tested and
//! written eight at a time, items written without being read unless a depth ties.
//!
//! The result cannot depend on the strategy, the split or the thread count: every fragment's
//! depth is a function of the triangle and the pixel alone, and pixels keep the nearest
//! `(depth, item)` (invariant 1; tested for every strategy).
//!
//! Cost: O(triangles + covered pixels of their boxes). For scenes where most triangles are
//! hidden, that is what the culling renderers avoid.
//!
//! ## Files, by stage
//! - this file: the public API ([`Rasterizer`], [`RasterConfig`], [`Draw`]) and the choice of
//!   strategy per pass;
//! - `project`: vertices to clip space, outcodes, snapping, the vertex cache, clipping;
//! - `setup` (scalar) and `setup8` (eight triangles in lanes): projected corners to
//!   [`TriSetup`] records;
//! - `sinks`: where set-up triangles go (tile bins, or the scan at once);
//! - `scan`: coverage and fragment writes;
//! - `threads`: the job system the parallel phases share (`Workers`);
//! - `merge`: sort-last drawing and its merge of private frames;
//! - `dispatch`: the entry points of the hot loops, compiled once per instruction set;
//! - `stencil`: the stencil pass (shadow volumes), on the same setup and coverage.

/// `impl AddAssign` for a struct of counters, field by field (the counts of draws and passes
/// add up).
macro_rules! add_assign_fields {
    ($ty:ty { $($field:ident),* $(,)? }) => {
        impl std::ops::AddAssign for $ty {
            fn add_assign(&mut self, o: Self) {
                $(self.$field += o.$field;)*
            }
        }
    };
}

mod dispatch;
mod helpers;
mod merge;
mod meshlets;
mod project;
mod scan;
mod setup;
#[cfg(target_arch = "x86_64")]
mod setup8;
mod sinks;
pub(crate) mod stencil;
#[cfg(test)]
mod tests;
mod threads;

use crate::frame::Frame;
use occult_core::simd::Isa;
use occult_core::{ItemId, Mat4, Mesh, View};
use std::ops::Range;
use std::time::Instant;

use helpers::Helpers;
pub use meshlets::{Meshlets, MAX_CLUSTER_VERTICES};
use project::{
    clip_and_setup, ProjVertex, Viewport, NEEDS_CLIP, NOT_FINITE, OUT_BOTTOM, OUT_LEFT, OUT_NEAR, OUT_OF_VIEW,
    OUT_RIGHT, OUT_TOP,
};
#[cfg(all(test, target_arch = "x86_64"))]
use scan::row_mask;
use scan::{box_in, depth_at, edge_functions, row_depth, solve_span, FrameTarget, SmallCover, MASKED, SMALL, TINY};
#[cfg(all(test, target_arch = "x86_64"))]
use setup::setup_triangle;
use setup::{draw_starts, setup_range, TriSetup, TriStream};
#[cfg(all(test, target_arch = "x86_64"))]
use sinks::{union_rect, EMPTY_RECT};
use sinks::{ChunkBins, SetupSink};
use threads::Workers;

/// Sub-pixel precision of snapped vertices, in bits.
pub const SUBPIXEL_BITS: u32 = 8;
const SUB: i64 = 1 << SUBPIXEL_BITS;
const HALF: i64 = SUB / 2;
/// Guard band half-width in pixels: vertices beyond it are clipped, so fixed-point coordinates
/// stay below 2^24 and edge products below 2^50.
const GUARD_PIXELS: f32 = 32768.0;
/// Triangles per setup chunk of the tile-binned strategy: a chunk's setup records (64 B each)
/// stay in L2.
pub const CHUNK_TRIANGLES: usize = 2 * 1024;

/// Rasterizer configuration. Results never depend on it, only speed does (and, through
/// [`RasterConfig::control`], whether a renderer finishes its frame).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RasterConfig {
    /// Worker threads; 0 uses the pool the caller runs in (outside any, rayon's global pool:
    /// all cores).
    pub threads: usize,
    /// Tile side in pixels, a power of two in 8..=1024, of the tile-binned path (forced, or
    /// sort-last's fallback): smaller balances load better, larger bins less.
    pub tile_size: u32,
    /// Skip back faces (clockwise on screen). Off by default: open meshes stay visible from
    /// behind. Every renderer compared against another must use the same setting.
    pub cull_backfaces: bool,
    /// Use the widest instruction set the processor offers (chosen at run time); `false`
    /// forces the baseline path. Frames are bit-identical either way (tested).
    pub simd: bool,
    /// How triangles are spread over threads (see the module doc). Frames are bit-identical
    /// whichever is used (tested); only speed differs.
    pub strategy: Strategy,
    /// Cancellation and progress of the frame being drawn ([`crate::FrameControl`]): inert by
    /// default. The rasterizer never reads it; it travels here so that the renderers, which
    /// hold a rasterizer wherever they submit a batch, check it there without passing it
    /// along (`occult-render`'s `RenderError::Cancelled`).
    pub control: crate::FrameControl,
}

/// How a draw is spread over threads.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Strategy {
    /// Direct on the calling thread on one thread. On several: sort-last over the threads for
    /// draws of 200,000 triangles or more; below, by bands for draws that this rasterizer's
    /// measured cost of a triangle makes long enough to share, unless their triangles are
    /// cheap (setup-bound) and the draw long beside the frame, which go sort-last (see
    /// `Rasterizer::shared_as`); the rest directly on the calling thread. The split was
    /// measured on two cores: on many, draws of large triangles may gain from
    /// [`Strategy::Binned`].
    #[default]
    Auto,
    /// Set up and scan each triangle at once, on the calling thread, whatever the thread
    /// count.
    Direct,
    /// Tile-binned setup and scan, on all threads.
    Binned,
    /// Direct workers into private frames, merged (falls back to tile-binned when the private
    /// frames cannot be allocated).
    SortLast,
    /// Every thread sets up every triangle and scans its own bands of rows (interleaved bands
    /// of 32 rows) of the frame itself: no private frames, no merge, the setup repeated. For
    /// draws whose fill outweighs their setup (few large triangles).
    Banded,
}

impl Default for RasterConfig {
    fn default() -> Self {
        Self {
            threads: 0,
            tile_size: 64,
            cull_backfaces: false,
            simd: true,
            strategy: Strategy::Auto,
            control: crate::FrameControl::default(),
        }
    }
}

/// Which triangles of a mesh a [`Draw`] sends.
#[derive(Clone, Debug)]
pub enum DrawTriangles<'a> {
    /// All of them (vertices are transformed once, shared by their triangles).
    All,
    /// A contiguous range of triangle indices.
    Range(Range<u32>),
    /// An explicit list of triangle indices (corners transformed eight at a time where the
    /// processor has AVX2, else through a small per-draw cache: shared corners of neighbouring
    /// triangles mostly once).
    List(&'a [u32]),
    /// The triangles of some clusters of the mesh's [`Meshlets`] (`list`: cluster indices, in
    /// drawing order): each cluster's vertices transformed once, eight at a time where the
    /// processor has AVX2, and shared by its triangles.
    Clusters {
        /// The mesh's clusters (built for this draw's mesh).
        meshlets: &'a Meshlets,
        /// Which of them.
        list: &'a [u32],
    },
}

impl DrawTriangles<'_> {
    /// The triangles sent, of `mesh`'s.
    pub fn count(&self, mesh: &Mesh) -> usize {
        self.len(mesh)
    }
    fn len(&self, mesh: &Mesh) -> usize {
        match self {
            Self::All => mesh.triangle_count(),
            Self::Range(r) => r.len(),
            Self::List(l) => l.len(),
            Self::Clusters { meshlets, list } => meshlets.list_len(list),
        }
    }
    #[inline]
    fn triangle_index(&self, j: usize) -> u32 {
        match self {
            Self::All => j as u32,
            Self::Range(r) => r.start + j as u32,
            Self::List(l) => l[j],
            Self::Clusters { meshlets, list } => meshlets.list_triangle(list, j),
        }
    }
}

/// One mesh instance (or part of it) to rasterize.
#[derive(Clone, Debug)]
pub struct Draw<'a> {
    /// The mesh.
    pub mesh: &'a Mesh,
    /// Which of its triangles.
    pub triangles: DrawTriangles<'a>,
    /// Object to clip space, formed by [`View::clip_from_object`].
    pub clip_from_object: Mat4,
    /// Item id of the mesh's triangle 0 in this instance; triangle `i` is `first_item + i`.
    pub first_item: ItemId,
}

/// What to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RasterMode {
    /// Depth and item id, under the (depth, item) rule.
    Full,
    /// Depth only (for occluders and depth structures); items are left untouched.
    DepthOnly,
}

/// Counts from one [`Rasterizer::draw`] call.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RasterCounts {
    /// Triangles handed in.
    pub triangles_submitted: u64,
    /// Triangles whose box held a pixel centre, with non-zero area, facing right, not beyond
    /// the far plane: the ones scanned, or for a box of at most 4 × 4 pixels whose centres
    /// all lie outside, found to cover none. A triangle that clipping cut into pieces counts
    /// once if any piece is (so never more than were submitted).
    pub triangles_rasterized: u64,
    /// Fragments that won their pixel when written.
    pub fragments_written: u64,
    /// Triangles of the passes shared over more than one thread (banded, sort-last or
    /// binned): those drawn as a large direct frame's are, at its rate.
    pub triangles_shared: u64,
}

add_assign_fields!(RasterCounts {
    triangles_submitted,
    triangles_rasterized,
    fragments_written,
    triangles_shared,
});

/// The rasterizer: configuration, thread pool and reusable scratch memory.
pub struct Rasterizer {
    config: RasterConfig,
    pool: Option<std::sync::Arc<rayon::ThreadPool>>,
    vertices: Vec<ProjVertex>,
    chunks: Vec<ChunkBins>,
    /// Depth and item buffers of the extra workers of sort-last draws, kept cleared.
    scratch: Vec<(Vec<f32>, Vec<ItemId>)>,
    /// False while a sort-last draw is in flight (a panic there leaves the scratch drawn).
    scratch_clean: bool,
    isa: Isa,
    /// Decaying sums of the thread time and the triangles of the measured draws (see
    /// [`Rasterizer::shared_as`]): their ratio is what a triangle costs one thread.
    measured: (f64, f64),
    /// The helper threads of banded draws, started at the first ([`helpers`]).
    helpers: Option<Helpers>,
    /// The helper threads could not be started (banded draws then run on the caller alone).
    helpers_failed: bool,
    /// The inclusive pixel box holding every fragment written since it was last taken (empty
    /// while `written_box[0] > written_box[2]`), see [`Rasterizer::take_written`].
    written_box: [u32; 4],
    /// Whether the last pass drawn ran on the calling thread alone, and its strategy, for
    /// tests of the choice.
    #[cfg(test)]
    last_pass: Option<(bool, Strategy)>,
}

impl std::fmt::Debug for Rasterizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rasterizer")
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

impl Rasterizer {
    /// Bytes of the scratch memory it keeps between draws: the projected vertices of whole
    /// meshes, the tile bins and set-up records, and the private frames of sort-last draws
    /// (each as big as a frame). Grows with the largest draw so far; not the frame drawn into.
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        let chunks: usize = self
            .chunks
            .iter()
            .map(|c| {
                c.records.capacity() * size_of::<TriSetup>()
                    + c.bins.capacity() * size_of::<Vec<u32>>()
                    + c.bins.iter().map(|b| b.capacity() * size_of::<u32>()).sum::<usize>()
            })
            .sum();
        let scratch: usize = self
            .scratch
            .iter()
            .map(|(d, i)| d.capacity() * size_of::<f32>() + i.capacity() * size_of::<ItemId>())
            .sum();
        self.vertices.capacity() * size_of::<ProjVertex>() + chunks + scratch
    }

    /// A rasterizer with its own pool of `config.threads` threads (with 0, it uses the pool
    /// each call runs in: rayon's global pool outside any).
    ///
    /// # Errors
    /// [`crate::RasterError::BadConfig`] for a tile size that is not a power of two in 8..=1024, or a thread pool
    /// that cannot be started.
    pub fn new(config: RasterConfig) -> Result<Self, crate::RasterError> {
        if !(8..=1024).contains(&config.tile_size) || !config.tile_size.is_power_of_two() {
            return Err(crate::RasterError::BadConfig(format!(
                "tile size {} is not a power of two in 8..=1024",
                config.tile_size
            )));
        }
        if config.threads > 1024 {
            return Err(crate::RasterError::BadConfig(format!(
                "{} threads is absurd",
                config.threads
            )));
        }
        let pool = if config.threads > 0 {
            Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(config.threads)
                    .build()
                    .map(std::sync::Arc::new)
                    .map_err(|e| crate::RasterError::BadConfig(format!("thread pool: {e}")))?,
            )
        } else {
            None
        };
        let isa = Isa::select(config.simd);
        Ok(Self {
            config,
            pool,
            vertices: Vec::new(),
            chunks: Vec::new(),
            scratch: Vec::new(),
            scratch_clean: true,
            measured: (0.0, 0.0),
            helpers: None,
            helpers_failed: false,
            written_box: sinks::EMPTY_RECT,
            #[cfg(test)]
            last_pass: None,
            isa,
        })
    }

    /// Faults in, ahead of the first frame, the buffer a draw projects whole meshes' vertices
    /// into, for draws of up to `vertices` vertices in all (a scene's vertex instances,
    /// [`occult_core::Scene::vertex_instance_count`]; capped at what one pass of a draw
    /// projects). The buffer grows with the largest draw anyway; reserved at preparation, a
    /// renderer's first large draw does not pay for fresh pages (about a third of a
    /// 2-million-triangle frame). Frames do not change.
    ///
    /// # Errors
    /// [`crate::RasterError::OutOfMemory`] when the buffer cannot be allocated.
    pub fn reserve_vertices(&mut self, vertices: u64) -> Result<(), crate::RasterError> {
        let n = usize::try_from(vertices)
            .unwrap_or(usize::MAX)
            .min(MAX_PROJECTED_VERTICES);
        if n > self.vertices.len() {
            let bytes = n * std::mem::size_of::<ProjVertex>();
            self.vertices
                .try_reserve_exact(n - self.vertices.len())
                .map_err(|_| crate::RasterError::OutOfMemory(bytes))?;
            self.vertices.resize(n, ProjVertex::default());
        }
        Ok(())
    }

    /// Makes, ahead of the first frame, the private frames that sort-last draws into frames of
    /// `width × height` use (one for each thread beyond the first), when this rasterizer may
    /// draw sort-last and a scene of `triangles` triangle instances can hand it a draw large
    /// enough. A first large draw then does not pay for their fresh pages (several
    /// milliseconds a frame of 1280×720). Frames do not change; a frame of another size makes
    /// its own, as before. False when the memory was refused: draws then make the frames
    /// themselves or fall back to binning, as without.
    pub fn reserve_frames(&mut self, width: u32, height: u32, triangles: u64) -> bool {
        let threads = self.thread_count();
        let sort_last = match self.config.strategy {
            Strategy::Auto => triangles >= SHARED_MIN_TRIANGLES as u64,
            Strategy::SortLast => true,
            Strategy::Direct | Strategy::Binned | Strategy::Banded => false,
        };
        if threads == 1 || !sort_last {
            return true;
        }
        self.ready_scratch(threads - 1, width as usize * height as usize)
    }

    /// The configuration.
    pub fn config(&self) -> &RasterConfig {
        &self.config
    }

    /// The instruction set the hot loops run with.
    pub fn isa_name(&self) -> &'static str {
        // The rasterizer has one wide path (AVX2); a wider processor runs it too.
        if self.isa.has_avx2() {
            "avx2"
        } else {
            "baseline"
        }
    }

    /// Worker threads used.
    pub fn thread_count(&self) -> usize {
        self.pool
            .as_ref()
            .map_or_else(rayon::current_num_threads, |p| p.current_num_threads())
    }

    /// This rasterizer's thread pool, for a caller's own parallel work kept apart from the
    /// rasterizer (`None`: it draws in the pool its caller runs in).
    pub fn thread_pool(&self) -> Option<std::sync::Arc<rayon::ThreadPool>> {
        self.pool.clone()
    }

    /// Runs `f` on this rasterizer's thread pool (so that callers' own parallel work uses the
    /// same threads).
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        match &self.pool {
            Some(p) => p.install(f),
            None => f(),
        }
    }

    /// Clears `frame`'s depth and items, in parallel on this rasterizer's threads.
    pub fn clear(&self, frame: &mut Frame) {
        self.clear_region(frame, [0, 0, frame.width(), frame.height()]);
    }

    /// Prepares `frame` for a view of the region `[x0, y0, x1, y1)`
    /// ([`occult_core::View::with_region`]; the whole frame for a whole view): clears it, and
    /// gives every other pixel [`crate::BLOCKED_DEPTH`] and no item, so that tests of what is
    /// drawn judge a box by its pixels in the region alone. A frame prepared for the same region
    /// frame after frame costs the clear of its own pixels only (and of those that left it).
    pub fn clear_region(&self, frame: &mut Frame, region: [u32; 4]) {
        let (w, h) = (frame.width(), frame.height());
        let [x0, y0, x1, y1] = [region[0].min(w), region[1].min(h), region[2].min(w), region[3].min(h)];
        let (before, foreign) = frame.prepare([x0, y0, x1, y1]);
        let width = w as usize;
        let (depth, items) = frame.buffers_unmarked();
        let mut fill = |[a0, b0, a1, b1]: [u32; 4], value: f32| {
            if a0 >= a1 || b0 >= b1 {
                return;
            }
            if a0 == 0 && a1 == w {
                let px = b0 as usize * width..b1 as usize * width;
                return self.fill(&mut depth[px.clone()], &mut items[px], value);
            }
            for y in b0 as usize..b1 as usize {
                let px = y * width + a0 as usize..y * width + a1 as usize;
                depth[px.clone()].fill(value);
                items[px].fill(occult_core::NO_ITEM);
            }
        };
        fill([x0, y0, x1, y1], crate::CLEAR_DEPTH);
        // What lies outside the region: above, below, left and right of it.
        let outside = [[0, 0, w, y0], [0, y1, w, h], [0, y0, x0, y1], [x1, y0, w, y1]];
        for [a0, b0, a1, b1] in outside {
            // Anything may lie outside after a caller's writes; else only what the last region
            // held (the rest is blocked already).
            let piece = if foreign {
                [a0, b0, a1, b1]
            } else {
                [
                    a0.max(before[0]),
                    b0.max(before[1]),
                    a1.min(before[2]),
                    b1.min(before[3]),
                ]
            };
            fill(piece, crate::BLOCKED_DEPTH);
        }
    }

    /// Sets `depth` to `value` and `items` to none, on this rasterizer's threads.
    fn fill(&self, depth: &mut [f32], items: &mut [occult_core::ItemId], value: f32) {
        if self.config.threads == 1 {
            depth.fill(value);
            items.fill(occult_core::NO_ITEM);
            return;
        }
        let jobs = depth.chunks_mut(1 << 16).zip(items.chunks_mut(1 << 16)).collect();
        self.workers(self.thread_count()).share(jobs, |(d, i)| {
            d.fill(value);
            i.fill(occult_core::NO_ITEM);
        });
    }

    /// The threads that parallel phases of a draw spread over: this rasterizer's pool, or the
    /// current one (see [`RasterConfig::threads`]).
    fn workers(&self, threads: usize) -> Workers<'_> {
        Workers {
            pool: self.pool.as_deref(),
            threads,
        }
    }

    /// Rasterizes `draws` into `frame` (not cleared first). A view restricted to a region
    /// ([`View::with_region`]) writes only its pixels, on the calling thread whatever the
    /// strategy.
    ///
    /// # Panics
    /// If the frame's size differs from the view's (a programmer error).
    pub fn draw(&mut self, view: &View, frame: &mut Frame, draws: &[Draw<'_>], mode: RasterMode) -> RasterCounts {
        assert_eq!(
            (frame.width(), frame.height()),
            (view.width(), view.height()),
            "frame and view sizes differ"
        );
        let vp = Viewport::new(view, &self.config);
        let [x0, y0, x1, y1] = vp.region;
        frame.note_drawn([x0, y0, x1 + 1, y1 + 1]);
        // A region (`View::with_region`) is one thread's share already.
        let shared = if view.is_band() {
            None
        } else {
            self.shared_as(draws, u64::from(view.width()) * u64::from(view.height()))
        };
        self.draw_in_passes(&vp, frame, draws, mode, MAX_PROJECTED_VERTICES, shared)
    }

    /// The pixels that the draws since the last call ([`Rasterizer::draw`], into any frame)
    /// wrote a fragment to lie in this rectangle (the box of the triangles that wrote any);
    /// `None` when they wrote none. Where a caller keeps a structure over the depth (a
    /// pyramid), only this rectangle changed. Starts empty again.
    pub fn take_written(&mut self) -> Option<crate::PixelRect> {
        let [x0, y0, x1, y1] = std::mem::replace(&mut self.written_box, sinks::EMPTY_RECT);
        (x0 <= x1 && y0 <= y1).then_some(crate::PixelRect {
            x0,
            y0,
            x1: x1 + 1,
            y1: y1 + 1,
        })
    }

    /// How `draws` are shared over the threads; `None` when they run directly on the calling
    /// thread, without binning, private frames or bands (a one-thread rasterizer never hands
    /// work to its pool, whatever the strategy):
    /// - on a one-thread rasterizer unless tile binning is forced;
    /// - under [`Strategy::Direct`], as it says;
    /// - under [`Strategy::Auto`], draws of fewer than [`SORT_LAST_MIN_TRIANGLES`] triangles
    ///   expected to take one thread less than [`BANDED_MIN_NS`] at the cost of a triangle
    ///   measured on this rasterizer's recent draws, or of fewer than [`BANDED_MIN_TRIANGLES`].
    ///   Longer ones are shared by bands ([`Strategy::Banded`]): each thread repeats the setup
    ///   and scans its share of the rows, which takes no longer than one thread doing both and
    ///   shares the fill, at the cost of handing the draw to a helper that waits spinning.
    ///   Only a long draw of cheap triangles (below [`FILL_HEAVY_NS`] each: setup-bound, the
    ///   part bands repeat), of at least [`SHARED_MIN_TRIANGLES`] and expected to take one
    ///   thread longer than [`SHARED_MIN_NS_PER_PIXEL`] per pixel of the frame (`pixels`),
    ///   goes sort-last below 200,000: sort-last's fixed part (waking the pool, merging the
    ///   private frames over the rows they drew) is more than it saves on shorter draws; tile
    ///   binning costs more still (each set-up triangle stored and read back, a large
    ///   triangle's spans found again in every tile it touches).
    ///
    /// Frames and counts are those of the binned path whichever is chosen (each scans a
    /// pixel's fragments in stream order).
    fn shared_as(&self, draws: &[Draw<'_>], pixels: u64) -> Option<Strategy> {
        match self.config.strategy {
            Strategy::Direct => None,
            Strategy::Binned => Some(Strategy::Binned),
            Strategy::SortLast | Strategy::Banded if self.config.threads == 1 => None,
            s @ (Strategy::SortLast | Strategy::Banded) => Some(s),
            Strategy::Auto => {
                if self.config.threads == 1 {
                    return None;
                }
                let total: usize = draws.iter().map(|d| d.triangles.len(d.mesh)).sum();
                let triangle_ns = self.triangle_ns();
                let expected = total as f64 * triangle_ns;
                if total >= SORT_LAST_MIN_TRIANGLES {
                    Some(Strategy::SortLast)
                } else if total < BANDED_MIN_TRIANGLES || expected < BANDED_MIN_NS {
                    None
                } else if triangle_ns < FILL_HEAVY_NS
                    && total >= SHARED_MIN_TRIANGLES
                    && expected >= SHARED_MIN_NS_PER_PIXEL * pixels as f64
                {
                    // Setup-bound and long: sort-last shares the setup, which bands repeat.
                    Some(Strategy::SortLast)
                } else {
                    Some(Strategy::Banded)
                }
            }
        }
    }

    /// What a triangle costs one thread to draw, ns, over this rasterizer's recent draws of
    /// at least [`MEASURED_MIN_TRIANGLES`] (the last ones weigh most); 0 before one.
    fn triangle_ns(&self) -> f64 {
        let (ns, triangles) = self.measured;
        if triangles > 0.0 {
            ns / triangles
        } else {
            0.0
        }
    }

    /// Learns from a pass of `triangles` that took its threads `thread_ns` together.
    fn measure(&mut self, triangles: usize, thread_ns: f64) {
        if triangles >= MEASURED_MIN_TRIANGLES {
            let (ns, n) = self.measured;
            self.measured = (0.5 * ns + thread_ns, 0.5 * n + triangles as f64);
        }
    }

    /// Draws in passes of consecutive draws whose whole meshes have at most `max_vertices`
    /// vertices together (a larger mesh goes alone): each pass projects those vertices ahead
    /// into one buffer, which thus stays bounded however many instances a scene draws. The
    /// frame is the same (order independence).
    fn draw_in_passes(
        &mut self,
        vp: &Viewport,
        frame: &mut Frame,
        draws: &[Draw<'_>],
        mode: RasterMode,
        max_vertices: usize,
        shared: Option<Strategy>,
    ) -> RasterCounts {
        let mut counts = RasterCounts::default();
        let mut rest = draws;
        loop {
            let (mut n, mut vertices) = (0, 0);
            while let Some(d) = rest.get(n) {
                let v = match d.triangles {
                    DrawTriangles::All => d.mesh.positions().len(),
                    _ => 0,
                };
                if n > 0 && vertices + v > max_vertices {
                    break;
                }
                vertices += v;
                n += 1;
            }
            let (pass, tail) = rest.split_at(n);
            counts += self.draw_pass(vp, frame, pass, mode, shared);
            rest = tail;
            if rest.is_empty() {
                return counts;
            }
        }
    }

    /// Draws one pass: on the calling thread alone when `shared` is `None`, else over this
    /// rasterizer's threads (see [`Workers`]) as `shared` says.
    fn draw_pass(
        &mut self,
        vp: &Viewport,
        frame: &mut Frame,
        draws: &[Draw<'_>],
        mode: RasterMode,
        shared: Option<Strategy>,
    ) -> RasterCounts {
        let threads = if shared.is_none() { 1 } else { self.thread_count() };
        // A handle of our own, apart from `self`'s fields that the phases borrow.
        let pool = self.pool.clone();
        let workers = Workers {
            pool: pool.as_deref(),
            threads,
        };
        let mut counts = RasterCounts::default();
        // Pre-transform the vertices of whole-mesh draws, in parallel.
        let mut vertex_offsets = Vec::with_capacity(draws.len());
        let mut vertex_total = 0usize;
        for d in draws {
            vertex_offsets.push(vertex_total);
            if matches!(d.triangles, DrawTriangles::All) {
                vertex_total += d.mesh.positions().len();
            }
        }
        // Every entry used is overwritten below. The buffer never shrinks: growing it again
        // after a smaller draw would write each entry twice (in a culled frame, small draws and
        // whole meshes alternate, and a whole mesh's vertices were filled before projected).
        if self.vertices.len() < vertex_total {
            self.vertices.resize(vertex_total, ProjVertex::default());
        }
        let isa = self.isa;
        {
            let mut rest = &mut self.vertices[..vertex_total];
            let mut jobs = Vec::new();
            for d in draws.iter().filter(|d| matches!(d.triangles, DrawTriangles::All)) {
                let (head, tail) = rest.split_at_mut(d.mesh.positions().len());
                rest = tail;
                jobs.push((d, head));
            }
            if threads == 1 {
                for (d, out) in jobs {
                    dispatch::project_all(isa, vp, &d.clip_from_object, d.mesh.positions(), out);
                }
            } else {
                let chunks = jobs
                    .into_iter()
                    .flat_map(|(d, out)| out.chunks_mut(4096).enumerate().map(move |(ci, out)| (d, ci, out)))
                    .collect();
                workers.share(chunks, |(d, ci, out)| {
                    dispatch::project_all(isa, vp, &d.clip_from_object, &d.mesh.positions()[ci * 4096..], out);
                });
            }
        }

        let draw_starts = draw_starts(draws);
        let total = draw_starts[draws.len()];
        counts.triangles_submitted = total as u64;

        let strategy = match shared {
            None => Strategy::Direct,
            Some(Strategy::Binned) => Strategy::Binned,
            Some(_) if threads == 1 => Strategy::Direct,
            // A small pass of a large draw (see `draw_in_passes`) is drawn directly too.
            Some(Strategy::SortLast) if self.config.strategy == Strategy::Auto && total < SHARED_MIN_TRIANGLES => {
                Strategy::Direct
            }
            Some(s) => s,
        };
        #[cfg(test)]
        {
            self.last_pass = Some((threads == 1, strategy));
        }
        if strategy == Strategy::Direct {
            let target = FrameTarget::new(frame);
            let t = Instant::now();
            // SAFETY: only this thread touches the frame while it is drawn.
            let (rasterized, written, dirty) = unsafe {
                let stream = TriStream::new(draws, &draw_starts, &vertex_offsets, &self.vertices);
                dispatch::draw_direct(self.isa, vp, &stream, 0..total, &target, mode)
            };
            self.written_box = sinks::union_rect(self.written_box, dirty);
            self.measure(total, t.elapsed().as_nanos() as f64);
            counts.triangles_rasterized = rasterized;
            counts.fragments_written = written;
            return counts;
        }
        if strategy == Strategy::Banded {
            if !self.helpers_failed && self.helpers.as_ref().is_none_or(|h| h.count() != threads - 1) {
                // Without helpers (a thread that cannot start), the bands are all the caller's,
                // and starting them is not tried again.
                self.helpers = Helpers::new(threads - 1).ok();
                self.helpers_failed = self.helpers.is_none();
            }
            let target = FrameTarget::new(frame);
            let stream = TriStream::new(draws, &draw_starts, &vertex_offsets, &self.vertices);
            let bands = threads as u32;
            let (target, stream) = (&target, &stream);
            /// A band's triangles rasterized, fragments written, thread time and written box.
            type BandResult = (u64, u64, f64, [u32; 4]);
            let results: Vec<std::sync::Mutex<BandResult>> = (0..bands)
                .map(|_| std::sync::Mutex::new((0, 0, 0.0, sinks::EMPTY_RECT)))
                .collect();
            let job = |band: usize| {
                let t = Instant::now();
                // SAFETY: each band is drawn once, and band `band` writes only its own rows.
                let (rasterized, written, dirty) =
                    unsafe { dispatch::draw_banded(isa, vp, stream, 0..total, target, mode, band as u32, bands) };
                *results[band].lock().unwrap_or_else(std::sync::PoisonError::into_inner) =
                    (rasterized, written, t.elapsed().as_nanos() as f64, dirty);
            };
            match &mut self.helpers {
                Some(h) => h.run(bands as usize, &job),
                None => (0..bands as usize).for_each(job),
            }
            let results: Vec<BandResult> = results
                .into_iter()
                .map(|r| r.into_inner().unwrap_or_else(std::sync::PoisonError::into_inner))
                .collect();
            for r in &results {
                self.written_box = sinks::union_rect(self.written_box, r.3);
            }
            // Every band set up every triangle: each counted them all.
            counts.triangles_rasterized = results[0].0;
            counts.fragments_written = results.iter().map(|r| r.1).sum();
            // Without helpers the caller draws every band in turn: not shared.
            counts.triangles_shared = if bands > 1 && self.helpers.is_some() {
                counts.triangles_submitted
            } else {
                0
            };
            // The threads' time together: the setup counted once per band, so a triangle's
            // cost is overestimated by the setup (draws stay banded the more readily).
            self.measure(total, results.iter().map(|r| r.2).sum());
            return counts;
        }
        if strategy == Strategy::SortLast {
            if let Some((rasterized, written, thread_ns, dirty)) =
                self.draw_sort_last(&workers, vp, frame, draws, &draw_starts, &vertex_offsets, mode)
            {
                self.written_box = sinks::union_rect(self.written_box, dirty);
                self.measure(total, thread_ns);
                counts.triangles_rasterized = rasterized;
                counts.fragments_written = written;
                // Blocks are handed out whole: a pass of one block is one worker's.
                counts.triangles_shared = if threads > 1 && total > merge::SORT_LAST_BLOCK {
                    counts.triangles_submitted
                } else {
                    0
                };
                return counts;
            }
        }
        let tile_count = (vp.tiles_x * vp.tiles_y) as usize;
        let chunks_per_round = threads.max(1) * 2;
        if self.chunks.len() < chunks_per_round {
            self.chunks.resize_with(chunks_per_round, ChunkBins::default);
        }
        for ch in &mut self.chunks {
            ch.bins.resize_with(tile_count, Vec::new);
        }
        let stream = TriStream::new(draws, &draw_starts, &vertex_offsets, &self.vertices);
        let target = FrameTarget::new(frame);
        let mut start = 0;
        while start < total {
            let round_end = (start + chunks_per_round * CHUNK_TRIANGLES).min(total);
            let used = (round_end - start).div_ceil(CHUNK_TRIANGLES);
            // Phase 1: setup and binning.
            let jobs = self.chunks[..used].iter_mut().enumerate().collect();
            workers.share(jobs, |(ci, ch)| {
                let lo = start + ci * CHUNK_TRIANGLES;
                let hi = (lo + CHUNK_TRIANGLES).min(round_end);
                ch.records.clear();
                for b in &mut ch.bins {
                    b.clear();
                }
                ch.rasterized = 0;
                dispatch::setup_range(isa, vp, &stream, lo..hi, ch);
            });
            counts.triangles_rasterized += self.chunks[..used].iter().map(|c| c.rasterized).sum::<u64>();
            // Phase 2: rasterize tile by tile.
            let chunks = &self.chunks[..used];
            let target = &target;
            let fragments: Vec<u64> = workers.share((0..tile_count).collect(), |tile| {
                // SAFETY: tiles are disjoint and each is scanned by exactly one task.
                unsafe { dispatch::scan_tile(isa, vp, chunks, tile, target, mode) }
            });
            for (tile, &n) in fragments.iter().enumerate() {
                if n > 0 {
                    self.written_box = sinks::union_rect(self.written_box, vp.tile_rect(tile));
                }
            }
            counts.fragments_written += fragments.iter().sum::<u64>();
            start = round_end;
        }
        if threads > 1 {
            counts.triangles_shared = counts.triangles_submitted;
        }
        counts
    }
}

/// Most vertices of whole-mesh draws projected ahead in one pass of a draw (16 bytes each).
const MAX_PROJECTED_VERTICES: usize = 1 << 22;

/// Draws at least this large go sort-last on several threads (below it, the calling thread
/// draws them directly unless they are long: see `Rasterizer::shared_as`).
const SORT_LAST_MIN_TRIANGLES: usize = 200_000;
/// Draws smaller than this never go sort-last below [`SORT_LAST_MIN_TRIANGLES`].
const SHARED_MIN_TRIANGLES: usize = 4096;
/// Draws whose triangles at least this many take the rasterizer's threads are measured.
const MEASURED_MIN_TRIANGLES: usize = 64;
/// Draws smaller than this stay on the calling thread however long they are measured to take
/// (a few triangles' cost is no guide to a draw's).
const BANDED_MIN_TRIANGLES: usize = 64;
/// A draw the automatic strategy keeps off sort-last is shared by bands when expected to take
/// one thread longer than this, ns (a helper that waits spinning takes a few microseconds to
/// start; one asleep, tens).
const BANDED_MIN_NS: f64 = 50_000.0;
/// Draws whose triangles cost one thread at least this much each, ns, are fill-bound: bands
/// share their fill (sort-last would share their setup, and pay a merge).
const FILL_HEAVY_NS: f64 = 100.0;
/// A setup-bound draw of fewer than [`SORT_LAST_MIN_TRIANGLES`] goes sort-last when expected
/// to take one thread more than this per pixel of the frame, ns (a whole frame's merge is a
/// few ns a pixel; chosen from 1, 2 and 4 on the suite's fill-heavy model views, on two cores,
/// before draws were banded).
const SHARED_MIN_NS_PER_PIXEL: f64 = 2.0;
