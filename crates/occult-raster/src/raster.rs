//! The exact triangle rasterizer: one triangle setup and one scan, driven three ways.
//!
//! - **Direct** (one thread): each triangle is set up and scanned at once, in submission order;
//!   consecutive triangles of a mesh touch neighbouring pixels, so the frame stays in cache.
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
//!   thread: binning it cost more than it saved in every renderer measured (see
//!   `Rasterizer::on_caller`).
//!
//! The calling thread drives every draw (and the stencil pass). On one thread it does all the
//! work itself (the rasterizer's one-thread pool serves only [`Rasterizer::install`]); on
//! several it hands each parallel phase to the pool as jobs that any thread may take (see
//! `Workers::share`) and waits for them.
//!
//! Setup, shared by all three: transform vertices (whole meshes: each vertex once per draw, in
//! parallel; index lists and ranges: per triangle, through a small per-draw cache so that the
//! corners neighbouring triangles share are mostly transformed once, or with AVX2 every corner,
//! eight at a time, which costs less), trivially reject by
//! outcodes, clip the rare triangle that crosses the near plane or the guard band, snap to fixed
//! point, reject empty boxes and zero areas, and fix the depth plane. Where the processor has
//! AVX2, vertices are projected and triangles set up eight at a time, in lanes
//! ([`setup8`]), with the same operations in the same order as the scalar path (tested bit
//! for bit). The scan derives exact integer edge functions (the 8-lane setup hands them over
//! for small boxes) and finds covered pixels with branch-free 8-pixel masks (boxes up to 64
//! pixels) or per-row integer span solving (larger ones).
//!
//! The result cannot depend on the strategy, the split or the thread count: every fragment's
//! depth is a function of the triangle and the pixel alone, and pixels keep the nearest
//! `(depth, item)` (invariant 1; tested for every strategy).
//!
//! Cost: O(triangles + covered pixels of their boxes). For scenes where most triangles are
//! hidden, that is what the culling renderers avoid.

use crate::frame::Frame;
use occult_core::glam::DVec4;
use occult_core::{ItemId, Mat4, Mesh, Vec3, Vec4, View};
use std::ops::Range;

#[cfg(target_arch = "x86_64")]
mod setup8;
pub(crate) mod stencil;

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

const OUT_LEFT: u32 = 1;
const OUT_RIGHT: u32 = 2;
const OUT_BOTTOM: u32 = 4;
const OUT_TOP: u32 = 8;
const OUT_NEAR: u32 = 16;
const OUT_OF_VIEW: u32 = OUT_LEFT | OUT_RIGHT | OUT_BOTTOM | OUT_TOP | OUT_NEAR;
const NEEDS_CLIP: u32 = 32;
const NOT_FINITE: u32 = 64;

/// Rasterizer configuration. Results never depend on it, only speed does.
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
}

/// How a draw is spread over threads.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Strategy {
    /// Direct on the calling thread on one thread, and on several for draws of fewer than
    /// 200,000 triangles; sort-last over the threads for larger ones (of which a pass of fewer,
    /// split off to bound memory, is drawn directly by one thread). The split was measured on
    /// two cores: on many, draws of large triangles may gain from [`Strategy::Binned`].
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
}

impl Default for RasterConfig {
    fn default() -> Self {
        Self {
            threads: 0,
            tile_size: 64,
            cull_backfaces: false,
            simd: true,
            strategy: Strategy::Auto,
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
}

impl DrawTriangles<'_> {
    fn len(&self, mesh: &Mesh) -> usize {
        match self {
            Self::All => mesh.triangle_count(),
            Self::Range(r) => r.len(),
            Self::List(l) => l.len(),
        }
    }
    #[inline]
    fn triangle_index(&self, j: usize) -> u32 {
        match self {
            Self::All => j as u32,
            Self::Range(r) => r.start + j as u32,
            Self::List(l) => l[j],
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
}

impl std::ops::AddAssign for RasterCounts {
    fn add_assign(&mut self, o: Self) {
        self.triangles_submitted += o.triangles_submitted;
        self.triangles_rasterized += o.triangles_rasterized;
        self.fragments_written += o.fragments_written;
    }
}

/// A vertex in clip space with its snapped screen position. The 8-lane setup loads and stores
/// it as one 16-byte vector of these four fields, in this order.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C)]
struct ProjVertex {
    x: i32,
    y: i32,
    z: f32,
    code: u32,
}

const _: () = assert!(std::mem::size_of::<ProjVertex>() == 16);

/// A triangle ready to scan: its snapped corners (1/256 pixel, oriented so that the edge
/// functions are non-negative inside), its pixel box, and its depth plane anchored at the centre
/// of pixel `(px0, py0)`. One cache line: the tile-binned scan re-derives the edge functions
/// from the corners, which costs less than moving them through memory (the direct sink takes
/// them from the 8-lane setup for small boxes, where they are at hand).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct TriSetup {
    x: [i32; 3],
    y: [i32; 3],
    px0: u16,
    py0: u16,
    px1: u16,
    py1: u16,
    /// Depth at the centre of pixel `(px0, py0)`.
    zc: f32,
    dzdx: f32,
    dzdy: f32,
    zmin: f32,
    zmax: f32,
    /// Larger side of the snapped corners' box, in whole pixels (saturating): decides whether
    /// edge functions fit i32 lanes. The pixel box above is clamped to the frame and says nothing
    /// about that: a triangle reaching into the guard band can show a tiny box on screen.
    extent: u16,
    /// Counter-clockwise on screen before the corners were reordered (a front face); read by
    /// the stencil pass, which counts by orientation.
    front: bool,
    item: ItemId,
}

const _: () = assert!(std::mem::size_of::<TriSetup>() == 64);
// Pixel boxes are stored in u16.
const _: () = assert!(occult_core::MAX_RESOLUTION <= u16::MAX as u32);

/// Per-frame constants.
#[derive(Clone, Copy, Debug)]
struct Viewport {
    width: u32,
    height: u32,
    fwidth: f32,
    fheight: f32,
    guard_x: f32,
    guard_y: f32,
    far_depth: f32,
    tile_size: u32,
    tile_shift: u32,
    tiles_x: u32,
    tiles_y: u32,
    cull_backfaces: bool,
}

impl Viewport {
    fn new(view: &View, config: &RasterConfig) -> Self {
        let (width, height) = (view.width(), view.height());
        let tile_size = config.tile_size;
        Self {
            width,
            height,
            fwidth: width as f32,
            fheight: height as f32,
            guard_x: 2.0 * GUARD_PIXELS / width as f32 - 1.0,
            guard_y: 2.0 * GUARD_PIXELS / height as f32 - 1.0,
            far_depth: view.far_depth(),
            tile_size,
            tile_shift: tile_size.trailing_zeros(),
            tiles_x: width.div_ceil(tile_size),
            tiles_y: height.div_ceil(tile_size),
            cull_backfaces: config.cull_backfaces,
        }
    }

    #[inline(always)]
    fn project(&self, clip_from_object: &Mat4, p: Vec3) -> ProjVertex {
        self.project_clip(to_clip(clip_from_object, p))
    }

    /// Outcodes and, when no clipping is needed, the snapped screen position and depth.
    #[inline(always)]
    fn project_clip(&self, c: Vec4) -> ProjVertex {
        let mut code = 0;
        if !c.is_finite() {
            return ProjVertex {
                x: 0,
                y: 0,
                z: 0.0,
                code: NOT_FINITE,
            };
        }
        code |= if c.x < -c.w { OUT_LEFT } else { 0 };
        code |= if c.x > c.w { OUT_RIGHT } else { 0 };
        code |= if c.y < -c.w { OUT_BOTTOM } else { 0 };
        code |= if c.y > c.w { OUT_TOP } else { 0 };
        code |= if c.z > c.w || c.w <= 0.0 {
            OUT_NEAR | NEEDS_CLIP
        } else {
            0
        };
        if c.x.abs() > self.guard_x * c.w || c.y.abs() > self.guard_y * c.w {
            code |= NEEDS_CLIP;
        }
        if code & NEEDS_CLIP != 0 {
            return ProjVertex {
                x: 0,
                y: 0,
                z: 0.0,
                code,
            };
        }
        let inv_w = 1.0 / c.w;
        let sx = (c.x * inv_w * 0.5 + 0.5) * self.fwidth;
        let sy = (0.5 - c.y * inv_w * 0.5) * self.fheight;
        let z = c.z * inv_w;
        // A `w` so small that its inverse overflows (no guard band test catches a vertex on the
        // axis) leaves nothing to draw.
        if !(sx.is_finite() && sy.is_finite() && z.is_finite()) {
            return ProjVertex {
                x: 0,
                y: 0,
                z: 0.0,
                code: NOT_FINITE,
            };
        }
        ProjVertex {
            x: snap(sx),
            y: snap(sy),
            z,
            code,
        }
    }
}

/// Object to clip space: the one expression every path uses, so that a vertex recomputed for
/// clipping has the same bits as when it was first projected.
#[inline(always)]
fn to_clip(clip_from_object: &Mat4, p: Vec3) -> Vec4 {
    *clip_from_object * p.extend(1.0)
}

/// Rounds a screen coordinate to the fixed-point grid (to nearest, ties to even), without
/// depending on SSE4.1's `roundss`.
#[inline(always)]
fn snap(v: f32) -> i32 {
    snap64(v as f64)
}

/// [`snap`] of a coordinate computed in f64 (a corner made by clipping).
#[inline(always)]
fn snap64(v: f64) -> i32 {
    const MAGIC: f64 = 6755399441055744.0; // 1.5 · 2^52
    ((v * SUB as f64 + MAGIC) - MAGIC) as i32
}

/// Reusable per-chunk storage.
#[derive(Default)]
struct ChunkBins {
    records: Vec<TriSetup>,
    bins: Vec<Vec<u32>>,
    rasterized: u64,
}

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
            #[cfg(test)]
            last_pass: None,
            isa,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &RasterConfig {
        &self.config
    }

    /// The instruction set the hot loops run with.
    pub fn isa_name(&self) -> &'static str {
        match self.isa {
            Isa::Baseline => "baseline",
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => "avx2",
        }
    }

    /// Worker threads used.
    pub fn thread_count(&self) -> usize {
        self.pool
            .as_ref()
            .map_or_else(rayon::current_num_threads, |p| p.current_num_threads())
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
        let (depth, items) = frame.buffers_mut();
        if self.config.threads == 1 {
            depth.fill(crate::CLEAR_DEPTH);
            items.fill(occult_core::NO_ITEM);
            return;
        }
        let jobs = depth.chunks_mut(1 << 16).zip(items.chunks_mut(1 << 16)).collect();
        self.workers(self.thread_count()).share(jobs, |(d, i)| {
            d.fill(crate::CLEAR_DEPTH);
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

    /// Rasterizes `draws` into `frame` (not cleared first).
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
        let single = self.on_caller(draws);
        self.draw_in_passes(&vp, frame, draws, mode, MAX_PROJECTED_VERTICES, single)
    }

    /// True when `draws` run directly on the calling thread, without binning or private
    /// frames (a one-thread rasterizer never hands work to its pool, whatever the strategy):
    /// - on a one-thread rasterizer unless tile binning is forced;
    /// - under [`Strategy::Direct`], as it says;
    /// - under [`Strategy::Auto`], draws of fewer than [`SORT_LAST_MIN_TRIANGLES`] triangles.
    ///   Tile binning would share them over the threads, but its fixed cost (waking them for
    ///   two parallel phases, each set-up triangle stored and read back, a large triangle's
    ///   spans found again in every tile it touches) was more than it saved for every
    ///   renderer's draws measured on two cores, even a few large triangles. Frames and
    ///   counts are those of the binned path (both scan each pixel's fragments in stream
    ///   order).
    fn on_caller(&self, draws: &[Draw<'_>]) -> bool {
        match self.config.strategy {
            Strategy::Direct => true,
            Strategy::Binned => false,
            Strategy::SortLast => self.config.threads == 1,
            Strategy::Auto => {
                let mut total = 0;
                self.config.threads == 1
                    || draws.iter().all(|d| {
                        total += d.triangles.len(d.mesh);
                        total < SORT_LAST_MIN_TRIANGLES
                    })
            }
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
        single: bool,
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
            counts += self.draw_pass(vp, frame, pass, mode, single);
            rest = tail;
            if rest.is_empty() {
                return counts;
            }
        }
    }

    /// Draws one pass: on the calling thread alone when `single`, else over this rasterizer's
    /// threads (see [`Workers`]).
    fn draw_pass(
        &mut self,
        vp: &Viewport,
        frame: &mut Frame,
        draws: &[Draw<'_>],
        mode: RasterMode,
        single: bool,
    ) -> RasterCounts {
        let threads = if single { 1 } else { self.thread_count() };
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
        // Every entry is overwritten below; resizing only writes entries the buffer never had.
        self.vertices.resize(vertex_total, ProjVertex::default());
        let isa = self.isa;
        {
            let mut rest = &mut self.vertices[..];
            let mut jobs = Vec::new();
            for d in draws.iter().filter(|d| matches!(d.triangles, DrawTriangles::All)) {
                let (head, tail) = rest.split_at_mut(d.mesh.positions().len());
                rest = tail;
                jobs.push((d, head));
            }
            if threads == 1 {
                for (d, out) in jobs {
                    isa.project_all(vp, &d.clip_from_object, d.mesh.positions(), out);
                }
            } else {
                let chunks = jobs
                    .into_iter()
                    .flat_map(|(d, out)| out.chunks_mut(4096).enumerate().map(move |(ci, out)| (d, ci, out)))
                    .collect();
                workers.share(chunks, |(d, ci, out)| {
                    isa.project_all(vp, &d.clip_from_object, &d.mesh.positions()[ci * 4096..], out);
                });
            }
        }

        let mut draw_starts = Vec::with_capacity(draws.len() + 1);
        let mut total = 0usize;
        for d in draws {
            draw_starts.push(total);
            total += d.triangles.len(d.mesh);
        }
        draw_starts.push(total);
        counts.triangles_submitted = total as u64;

        let strategy = match self.config.strategy {
            // A smaller pass of a large draw (see `draw_in_passes`) is drawn directly too.
            Strategy::Auto if threads > 1 && total >= SORT_LAST_MIN_TRIANGLES => Strategy::SortLast,
            Strategy::Auto => Strategy::Direct,
            Strategy::SortLast if threads == 1 => Strategy::Direct,
            s => s,
        };
        #[cfg(test)]
        {
            self.last_pass = Some((threads == 1, strategy));
        }
        if strategy == Strategy::Direct {
            let target = FrameTarget::new(frame);
            // SAFETY: only this thread touches the frame while it is drawn.
            let (rasterized, written, _) = unsafe {
                self.isa.draw_direct(
                    vp,
                    draws,
                    &draw_starts,
                    &vertex_offsets,
                    &self.vertices,
                    0..total,
                    &target,
                    mode,
                )
            };
            counts.triangles_rasterized = rasterized;
            counts.fragments_written = written;
            return counts;
        }
        if strategy == Strategy::SortLast {
            if let Some((rasterized, written)) =
                self.draw_sort_last(&workers, vp, frame, draws, &draw_starts, &vertex_offsets, total, mode)
            {
                counts.triangles_rasterized = rasterized;
                counts.fragments_written = written;
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
        let vertices = &self.vertices[..];
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
                isa.setup_range(vp, draws, &draw_starts, &vertex_offsets, vertices, lo..hi, ch);
            });
            counts.triangles_rasterized += self.chunks[..used].iter().map(|c| c.rasterized).sum::<u64>();
            // Phase 2: rasterize tile by tile.
            let chunks = &self.chunks[..used];
            let target = &target;
            let fragments: u64 = workers
                .share((0..tile_count).collect(), |tile| {
                    let tx = tile as u32 % vp.tiles_x;
                    let ty = tile as u32 / vp.tiles_x;
                    let rect = [
                        tx * vp.tile_size,
                        ty * vp.tile_size,
                        ((tx + 1) * vp.tile_size).min(vp.width) - 1,
                        ((ty + 1) * vp.tile_size).min(vp.height) - 1,
                    ];
                    // SAFETY: tiles are disjoint and each is scanned by exactly one task.
                    unsafe { isa.scan_tile(vp, chunks, tile, rect, target, mode) }
                })
                .into_iter()
                .sum();
            counts.fragments_written += fragments;
            start = round_end;
        }
        counts
    }
}

impl Rasterizer {
    /// Sort-last drawing for large draws on several threads: worker `k` draws the `k`-th part of
    /// the triangle stream directly (no binning) into the frame (`k = 0`) or a private scratch
    /// frame, and the scratch frames are then merged into the frame under the same (depth, item)
    /// rule, over the box each worker touched only, and cleared there for the next draw.
    #[allow(clippy::too_many_arguments)]
    fn draw_sort_last(
        &mut self,
        workers: &Workers<'_>,
        vp: &Viewport,
        frame: &mut Frame,
        draws: &[Draw<'_>],
        draw_starts: &[usize],
        vertex_offsets: &[usize],
        total: usize,
        mode: RasterMode,
    ) -> Option<(u64, u64)> {
        let parts = workers.threads;
        let (w, h) = (vp.width as usize, vp.height as usize);
        // Private frames are kept cleared between draws; one a panic left drawn is dropped.
        if !self.scratch_clean {
            self.scratch.clear();
        }
        self.scratch.retain(|(d, _)| d.len() == w * h);
        while self.scratch.len() < parts - 1 {
            let (mut d, mut i) = (Vec::new(), Vec::new());
            if d.try_reserve_exact(w * h).is_err() || i.try_reserve_exact(w * h).is_err() {
                return None;
            }
            d.resize(w * h, crate::CLEAR_DEPTH);
            i.resize(w * h, occult_core::NO_ITEM);
            self.scratch.push((d, i));
        }
        self.scratch_clean = false;
        let isa = self.isa;
        let vertices = &self.vertices[..];
        let mut targets: Vec<FrameTarget> = vec![FrameTarget::new(frame)];
        for (d, i) in self.scratch.iter_mut().take(parts - 1) {
            targets.push(FrameTarget {
                depth: d.as_mut_ptr(),
                items: i.as_mut_ptr(),
                width: w,
            });
        }
        let results: Vec<(u64, u64, Vec<[u32; 4]>)> = workers.share((0..parts).collect(), |k| {
            let target = &targets[k];
            // Worker k takes every parts-th block: each gets a share of near and far, large
            // and small triangles, and a block is long enough to keep the frame in cache.
            let (mut rasterized, mut written, mut boxes) = (0, 0, Vec::new());
            for start in (k * SORT_LAST_BLOCK..total).step_by(parts * SORT_LAST_BLOCK) {
                let range = start..(start + SORT_LAST_BLOCK).min(total);
                // SAFETY: each worker owns its own frame (the real one or a scratch one).
                let (r, f, d) =
                    unsafe { isa.draw_direct(vp, draws, draw_starts, vertex_offsets, vertices, range, target, mode) };
                rasterized += r;
                written += f;
                if d[0] <= d[2] && d[1] <= d[3] {
                    boxes.push(d);
                }
            }
            (rasterized, written, boxes)
        });
        let (depth, items) = frame.buffers_mut();
        for (k, (_, _, boxes)) in results.iter().enumerate().skip(1) {
            // The merge reads and resets only each row's span of the boxes of this worker's
            // blocks, not their bounding box: where the blocks of a coherent stream touch bands
            // of the frame, the merge (memory bound) skips the rows between them.
            let Some(spans) = row_spans(boxes, h) else { continue };
            let (sd, si) = &mut self.scratch[k - 1];
            let rows = MERGE_ROWS * w;
            let jobs = depth
                .chunks_mut(rows)
                .zip(items.chunks_mut(rows))
                .zip(sd.chunks_mut(rows))
                .zip(si.chunks_mut(rows))
                .zip(spans.chunks(MERGE_ROWS))
                .collect();
            workers.share(jobs, |((((d, it), sd), si), spans)| {
                let rows = d
                    .chunks_mut(w)
                    .zip(it.chunks_mut(w))
                    .zip(sd.chunks_mut(w))
                    .zip(si.chunks(w));
                for ((((d, it), sd), si), &(x0, x1)) in rows.zip(spans) {
                    let (x0, x1) = (x0 as usize, x1 as usize);
                    if x0 < x1 {
                        isa.merge_row(&mut d[x0..x1], &mut it[x0..x1], &mut sd[x0..x1], &si[x0..x1], mode);
                    }
                }
            });
        }
        self.scratch_clean = true;
        Some(results.iter().fold((0, 0), |(r, f), &(rr, ff, _)| (r + rr, f + ff)))
    }
}

/// The threads a draw's parallel phases run on: a rasterizer's own pool, or (`None`) the pool
/// the caller runs in, rayon's global one outside any.
struct Workers<'a> {
    pool: Option<&'a rayon::ThreadPool>,
    threads: usize,
}

impl Workers<'_> {
    /// Runs `job` on each of `jobs` and returns the results in the jobs' order. On one thread,
    /// or for a single job, on the calling thread; else on up to `threads` tasks spawned into
    /// the pool, each taking the next job from a counter when it finishes one, so any thread
    /// may run any job (callers' jobs give the same results on any thread, in any order), and
    /// a thread that is busy or blocked elsewhere only means another runs more. (With as many
    /// jobs as threads, as sort-last's workers are, a thread that runs slower still holds up
    /// the end by its share.)
    ///
    /// The tasks are spawned from the calling thread, which (outside the pool) injects them,
    /// waking a sleeping thread per task. Draws used to run inside the pool (`install`) and
    /// split with `rayon::join`, whose second half waits on the first thread's queue to be
    /// stolen. On the two-core VMs this project is measured on, after a two-thread pool had
    /// idled 20 ms, that second half started a median 2.4–2.8 ms after the call (both halves
    /// ran on one thread in a third of the rounds), the later of two tasks spawned from
    /// outside 0.09–0.24 ms after it (`cargo run --release -p occult-bench --example
    /// thread_scaling wake 60`, four runs). A caller inside the pool spawns onto its own
    /// queue and runs the jobs itself while it waits, as a join does.
    fn share<T: Send, R: Send>(&self, jobs: Vec<T>, job: impl Fn(T) -> R + Sync) -> Vec<R> {
        use std::sync::atomic::{AtomicUsize, Ordering};
        use std::sync::{Mutex, PoisonError};
        if self.threads <= 1 || jobs.len() <= 1 {
            return jobs.into_iter().map(job).collect();
        }
        let tasks = self.threads.min(jobs.len());
        // No job runs while a slot is locked, so no slot is poisoned; a poisoned one would
        // still be read.
        let slots: Vec<Mutex<(Option<T>, Option<R>)>> = jobs.into_iter().map(|j| Mutex::new((Some(j), None))).collect();
        let lock = |i: usize| slots[i].lock().unwrap_or_else(PoisonError::into_inner);
        let next = AtomicUsize::new(0);
        let work = || loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            if i >= slots.len() {
                break;
            }
            // The counter hands each index out once.
            let taken = lock(i).0.take();
            if let Some(j) = taken {
                let r = job(j);
                lock(i).1 = Some(r);
            }
        };
        let work = &work;
        match self.pool {
            Some(p) => p.in_place_scope(|scope| (0..tasks).for_each(|_| scope.spawn(move |_| work()))),
            None => rayon::in_place_scope(|scope| (0..tasks).for_each(|_| scope.spawn(move |_| work()))),
        }
        // A job that panicked ended the scope above with its panic: every slot has its result.
        slots
            .into_iter()
            .map(|s| {
                s.into_inner()
                    .unwrap_or_else(PoisonError::into_inner)
                    .1
                    .expect("every job ran: a panic in one ends the scope with it")
            })
            .collect()
    }
}

/// Per row of a `height`-row frame, the half-open pixel span `x0..x1` that the inclusive boxes
/// touch (`x0 == x1`: none); `None` when there are no boxes.
fn row_spans(boxes: &[[u32; 4]], height: usize) -> Option<Vec<(u32, u32)>> {
    if boxes.is_empty() {
        return None;
    }
    let mut spans = vec![(u32::MAX, 0u32); height];
    for b in boxes {
        for span in &mut spans[b[1] as usize..=b[3] as usize] {
            *span = (span.0.min(b[0]), span.1.max(b[2] + 1));
        }
    }
    for span in &mut spans {
        span.0 = span.0.min(span.1);
    }
    Some(spans)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
unsafe fn merge_row_avx2(d: &mut [f32], it: &mut [ItemId], sd: &mut [f32], si: &[ItemId], mode: RasterMode) {
    merge_row(d, it, sd, si, mode)
}

/// See [`Isa::merge_row`]. The row goes by runs of [`MERGE_RUN`] pixels: a run the worker
/// left clear (the rows between its triangles, the parts of the frame the other workers drew)
/// costs only the read of its private depths; the others are merged branch-free, so that the
/// compiler vectorizes them (a branch per pixel on whether the worker drew it mispredicts
/// along the borders of everything drawn), and their private depths reset.
#[inline(always)]
fn merge_row(d: &mut [f32], it: &mut [ItemId], sd: &mut [f32], si: &[ItemId], mode: RasterMode) {
    let n = d.len();
    let (it, sd, si) = (&mut it[..n], &mut sd[..n], &si[..n]);
    let mut dc = d.chunks_exact_mut(MERGE_RUN);
    let mut ic = it.chunks_exact_mut(MERGE_RUN);
    let mut sdc = sd.chunks_exact_mut(MERGE_RUN);
    let mut sic = si.chunks_exact(MERGE_RUN);
    for (((d, it), sd), si) in (&mut dc).zip(&mut ic).zip(&mut sdc).zip(&mut sic) {
        // Not an early-exit search: a fold over the run that the compiler vectorizes.
        let drawn = sd.iter().fold(false, |drawn, &s| drawn | (s != crate::CLEAR_DEPTH));
        if drawn {
            merge_run(d, it, sd, si, mode);
        }
    }
    merge_run(
        dc.into_remainder(),
        ic.into_remainder(),
        sdc.into_remainder(),
        sic.remainder(),
        mode,
    );
}

/// Merges one run of private pixels into the frame's, branch-free, and clears their depths.
#[inline(always)]
fn merge_run(d: &mut [f32], it: &mut [ItemId], sd: &mut [f32], si: &[ItemId], mode: RasterMode) {
    let n = d.len();
    let (it, sd, si) = (&mut it[..n], &mut sd[..n], &si[..n]);
    if mode == RasterMode::Full {
        for x in 0..n {
            let (s, t) = (sd[x], d[x]);
            // A clear private pixel was not drawn: its item is stale and must lose. A fragment
            // always beats a clear pixel, so the rule is keep_fragment's for drawn pixels.
            let win = s != crate::CLEAR_DEPTH && (s > t || (s == t && si[x] < it[x]));
            d[x] = if win { s } else { t };
            it[x] = if win { si[x] } else { it[x] };
        }
    } else {
        for x in 0..n {
            // As in full mode, a clear private pixel loses even to a frame depth below it
            // (whether its run was skipped or not).
            let win = sd[x] != crate::CLEAR_DEPTH && sd[x] > d[x];
            d[x] = if win { sd[x] } else { d[x] };
        }
    }
    // Only depth is reset: a private item matters only where the private depth is not clear,
    // so stale items are never read.
    sd.fill(crate::CLEAR_DEPTH);
}

/// Pixels of a sort-last merge run: a run the worker left clear is skipped (see `merge_row`).
/// Sixteen: 64 bytes of depths (runs start at a span's first pixel, not at a cache line).
const MERGE_RUN: usize = 16;

/// Most vertices of whole-mesh draws projected ahead in one pass of a draw (16 bytes each).
const MAX_PROJECTED_VERTICES: usize = 1 << 22;

/// Draws at least this large go sort-last on several threads (below it, the calling thread
/// draws them directly: see `Rasterizer::on_caller`).
const SORT_LAST_MIN_TRIANGLES: usize = 200_000;

/// Rows of the frame per job of a sort-last merge.
const MERGE_ROWS: usize = 8;

/// Triangles per block handed round-robin to the workers of a sort-last draw.
const SORT_LAST_BLOCK: usize = 16 * 1024;

/// An empty pixel box.
const EMPTY_RECT: [u32; 4] = [u32::MAX, u32::MAX, 0, 0];

/// The smallest inclusive pixel box holding boxes `a` and `b` (either may be empty, as
/// [`EMPTY_RECT`]).
#[inline(always)]
fn union_rect(a: [u32; 4], b: [u32; 4]) -> [u32; 4] {
    [a[0].min(b[0]), a[1].min(b[1]), a[2].max(b[2]), a[3].max(b[3])]
}

/// Raw access to a frame's buffers, shared by tile tasks that write disjoint pixels.
struct FrameTarget {
    depth: *mut f32,
    items: *mut ItemId,
    width: usize,
}

// SAFETY: the pointers are only written through `scan_triangle`, whose callers guarantee that
// concurrent calls touch disjoint pixels (one task per tile), and the frame outlives the draw.
unsafe impl Sync for FrameTarget {}
unsafe impl Send for FrameTarget {}

impl FrameTarget {
    fn new(frame: &mut Frame) -> Self {
        let width = frame.width() as usize;
        let (depth, items) = frame.buffers_mut();
        Self {
            depth: depth.as_mut_ptr(),
            items: items.as_mut_ptr(),
            width,
        }
    }
}

/// The instruction set of the hot loops, chosen once at run time. The same Rust code is compiled
/// for each; Rust never contracts floating-point operations, so results are bit-identical.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Isa {
    Baseline,
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Isa {
    fn select(simd: bool) -> Self {
        #[cfg(target_arch = "x86_64")]
        if simd
            && is_x86_feature_detected!("avx2")
            && is_x86_feature_detected!("bmi1")
            && is_x86_feature_detected!("bmi2")
            && is_x86_feature_detected!("lzcnt")
            && is_x86_feature_detected!("popcnt")
        {
            return Isa::Avx2;
        }
        let _ = simd;
        Isa::Baseline
    }

    /// Merges one row of a worker's private frame into the frame under the (depth, item) rule
    /// and resets the private depth to clear.
    fn merge_row(self, d: &mut [f32], it: &mut [ItemId], sd: &mut [f32], si: &[ItemId], mode: RasterMode) {
        match self {
            Isa::Baseline => merge_row(d, it, sd, si, mode),
            // SAFETY: `select` checked that the processor has these features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { merge_row_avx2(d, it, sd, si, mode) },
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn setup_range(
        self,
        vp: &Viewport,
        draws: &[Draw<'_>],
        draw_starts: &[usize],
        vertex_offsets: &[usize],
        vertices: &[ProjVertex],
        range: Range<usize>,
        out: &mut ChunkBins,
    ) {
        match self {
            Isa::Baseline => setup_range::<false>(vp, draws, draw_starts, vertex_offsets, vertices, range, out),
            // SAFETY: `select` checked that the processor has these features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { setup_range_avx2(vp, draws, draw_starts, vertex_offsets, vertices, range, out) },
        }
    }

    /// Projects `positions` into `out` (as many as `out` holds).
    fn project_all(self, vp: &Viewport, clip_from_object: &Mat4, positions: &[Vec3], out: &mut [ProjVertex]) {
        match self {
            Isa::Baseline => project_all(vp, clip_from_object, positions, out),
            // SAFETY: `select` checked that the processor has these features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { project_all_avx2(vp, clip_from_object, positions, out) },
        }
    }

    /// Sets up and scans `range` of the triangle stream at once over the whole frame;
    /// returns (triangles rasterized, fragments written, inclusive pixel box touched).
    ///
    /// # Safety
    /// No other thread may access `target` during the call.
    #[allow(clippy::too_many_arguments)]
    unsafe fn draw_direct(
        self,
        vp: &Viewport,
        draws: &[Draw<'_>],
        draw_starts: &[usize],
        vertex_offsets: &[usize],
        vertices: &[ProjVertex],
        range: Range<usize>,
        target: &FrameTarget,
        mode: RasterMode,
    ) -> (u64, u64, [u32; 4]) {
        match self {
            // SAFETY: forwarded.
            Isa::Baseline => unsafe {
                draw_direct::<false>(vp, draws, draw_starts, vertex_offsets, vertices, range, target, mode)
            },
            // SAFETY: forwarded; `select` checked the processor's features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe {
                draw_direct_avx2(vp, draws, draw_starts, vertex_offsets, vertices, range, target, mode)
            },
        }
    }

    /// # Safety
    /// As [`scan_tile`].
    unsafe fn scan_tile(
        self,
        vp: &Viewport,
        chunks: &[ChunkBins],
        tile: usize,
        rect: [u32; 4],
        target: &FrameTarget,
        mode: RasterMode,
    ) -> u64 {
        match self {
            // SAFETY: forwarded.
            Isa::Baseline => unsafe { scan_tile::<false>(vp, chunks, tile, rect, target, mode) },
            // SAFETY: forwarded; `select` checked the processor's features.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { scan_tile_avx2(vp, chunks, tile, rect, target, mode) },
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
#[allow(clippy::too_many_arguments)]
unsafe fn setup_range_avx2(
    vp: &Viewport,
    draws: &[Draw<'_>],
    draw_starts: &[usize],
    vertex_offsets: &[usize],
    vertices: &[ProjVertex],
    range: Range<usize>,
    out: &mut ChunkBins,
) {
    setup_range::<true>(vp, draws, draw_starts, vertex_offsets, vertices, range, out)
}

#[inline(always)]
fn project_all(vp: &Viewport, clip_from_object: &Mat4, positions: &[Vec3], out: &mut [ProjVertex]) {
    for (o, &p) in out.iter_mut().zip(positions) {
        *o = vp.project(clip_from_object, p);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
unsafe fn project_all_avx2(vp: &Viewport, clip_from_object: &Mat4, positions: &[Vec3], out: &mut [ProjVertex]) {
    let n = out.len().min(positions.len());
    let whole = n - n % setup8::LANES;
    for (o, p) in out[..whole]
        .chunks_exact_mut(setup8::LANES)
        .zip(positions.chunks_exact(setup8::LANES))
    {
        // SAFETY: `select` checked the processor's features; the chunks hold eight each.
        unsafe { setup8::project8_avx2(vp, clip_from_object, p, o) };
    }
    project_all(vp, clip_from_object, &positions[whole..n], &mut out[whole..n])
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
#[allow(clippy::too_many_arguments)]
unsafe fn draw_direct_avx2(
    vp: &Viewport,
    draws: &[Draw<'_>],
    draw_starts: &[usize],
    vertex_offsets: &[usize],
    vertices: &[ProjVertex],
    range: Range<usize>,
    target: &FrameTarget,
    mode: RasterMode,
) -> (u64, u64, [u32; 4]) {
    // SAFETY: forwarded.
    unsafe { draw_direct::<true>(vp, draws, draw_starts, vertex_offsets, vertices, range, target, mode) }
}

/// The body of [`Isa::draw_direct`], compiled once per instruction set.
///
/// # Safety
/// No other thread may access `target` during the call.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn draw_direct<const AVX2: bool>(
    vp: &Viewport,
    draws: &[Draw<'_>],
    draw_starts: &[usize],
    vertex_offsets: &[usize],
    vertices: &[ProjVertex],
    range: Range<usize>,
    target: &FrameTarget,
    mode: RasterMode,
) -> (u64, u64, [u32; 4]) {
    let rect = [0, 0, vp.width - 1, vp.height - 1];
    let mut sink = DirectSink::<AVX2> {
        target,
        rect,
        mode,
        rasterized: 0,
        written: 0,
        dirty: EMPTY_RECT,
    };
    setup_range::<AVX2>(vp, draws, draw_starts, vertex_offsets, vertices, range, &mut sink);
    (sink.rasterized, sink.written, sink.dirty)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,popcnt,lzcnt")]
unsafe fn scan_tile_avx2(
    vp: &Viewport,
    chunks: &[ChunkBins],
    tile: usize,
    rect: [u32; 4],
    target: &FrameTarget,
    mode: RasterMode,
) -> u64 {
    // SAFETY: forwarded.
    unsafe { scan_tile::<true>(vp, chunks, tile, rect, target, mode) }
}

/// Scans every triangle binned to `tile` (inclusive pixel rectangle `rect`).
///
/// # Safety
/// No other thread may access the pixels of `rect` in `target` during the call.
#[inline(always)]
unsafe fn scan_tile<const AVX2: bool>(
    vp: &Viewport,
    chunks: &[ChunkBins],
    tile: usize,
    rect: [u32; 4],
    target: &FrameTarget,
    mode: RasterMode,
) -> u64 {
    let mut written = 0;
    for ch in chunks {
        for &r in &ch.bins[tile] {
            // SAFETY: forwarded.
            written += unsafe { scan_triangle::<AVX2>(vp, &ch.records[r as usize], rect, target, mode) };
        }
    }
    written
}

/// Sets up and bins the triangles `range` of the global stream: one by one, or with `AVX2`
/// (only where the processor has it) eight at a time through [`setup8::Batch`].
#[inline(always)]
fn setup_range<const AVX2: bool>(
    vp: &Viewport,
    draws: &[Draw<'_>],
    draw_starts: &[usize],
    vertex_offsets: &[usize],
    vertices: &[ProjVertex],
    range: Range<usize>,
    out: &mut impl SetupSink,
) {
    let mut d = draw_starts.partition_point(|&s| s <= range.start) - 1;
    let mut t = range.start;
    let mut cache = VertexCache::new();
    #[cfg(target_arch = "x86_64")]
    let mut batch = setup8::Batch::new();
    // Where the 8-lane setup runs, each triangle joins the batch (flushed when full); the
    // scalar setup takes it at once otherwise.
    let mut emit = |v: [&ProjVertex; 3], indices: [u32; 3], d: usize, item: ItemId, out: &mut _| {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // Trivial rejects (most of a scene outside the view) never take a lane.
            if v[0].code & v[1].code & v[2].code & OUT_OF_VIEW != 0
                || (v[0].code | v[1].code | v[2].code) & NOT_FINITE != 0
            {
                return;
            }
            batch.push(v, d, item);
            if batch.is_full() {
                // SAFETY: the AVX2 instantiation only runs where `Isa::select` found AVX2.
                unsafe { setup8::setup8_avx2(vp, draws, &mut batch, out) };
            }
            return;
        }
        let draw = &draws[d];
        let corners = || indices.map(|i| draw.mesh.positions()[i as usize]);
        setup_triangle(vp, v.map(|p| *p), &draw.clip_from_object, corners, item, out);
    };
    while t < range.end {
        while draw_starts[d + 1] <= t {
            d += 1;
        }
        let draw = &draws[d];
        let end = draw_starts[d + 1].min(range.end);
        let mesh = draw.mesh;
        let tris = mesh.triangles();
        match &draw.triangles {
            DrawTriangles::All => {
                let verts = &vertices[vertex_offsets[d]..vertex_offsets[d] + mesh.positions().len()];
                let first = t - draw_starts[d];
                for (j, &[i0, i1, i2]) in tris[first..end - draw_starts[d]]
                    .iter()
                    .enumerate()
                    .map(|(k, t)| (first + k, t))
                {
                    // SAFETY: `verts` holds one entry per position of the mesh (sliced with a
                    // check above), and `Mesh` guarantees that every index names a position
                    // (checked by `Mesh::new`, its only constructor; fields private, see its
                    // doc). The loop runs once per triangle of the scene: three bounds checks
                    // were a tenth of its instructions.
                    debug_assert!([i0, i1, i2].iter().all(|&i| (i as usize) < verts.len()));
                    let v = unsafe {
                        [
                            verts.get_unchecked(i0 as usize),
                            verts.get_unchecked(i1 as usize),
                            verts.get_unchecked(i2 as usize),
                        ]
                    };
                    emit(v, [i0, i1, i2], d, draw.first_item + j as u64, out);
                }
            }
            #[cfg(target_arch = "x86_64")]
            sel if AVX2 => {
                // Corners projected eight at a time, in lanes: cheaper than the cache below even
                // when every corner is shared by six triangles.
                let pos = mesh.positions();
                let m = &draw.clip_from_object;
                let (mut j, last) = (t - draw_starts[d], end - draw_starts[d]);
                while j < last {
                    let n = (last - j).min(setup8::LANES);
                    let mut triangle = [0u32; setup8::LANES];
                    let mut indices = [[0u32; 3]; setup8::LANES];
                    let mut corners = [[Vec3::ZERO; setup8::LANES]; 3];
                    for k in 0..n {
                        triangle[k] = sel.triangle_index(j + k);
                        indices[k] = tris[triangle[k] as usize];
                        for c in 0..3 {
                            corners[c][k] = pos[indices[k][c] as usize];
                        }
                    }
                    let mut v = [[ProjVertex::default(); setup8::LANES]; 3];
                    for c in 0..3 {
                        // SAFETY: the AVX2 instantiation only runs where `Isa::select` found AVX2.
                        unsafe { setup8::project8_avx2(vp, m, &corners[c], &mut v[c]) };
                    }
                    for k in 0..n {
                        let item = draw.first_item + triangle[k] as u64;
                        emit([&v[0][k], &v[1][k], &v[2][k]], indices[k], d, item, out);
                    }
                    j += n;
                }
            }
            sel => {
                let pos = mesh.positions();
                let m = &draw.clip_from_object;
                cache.reset();
                for j in (t - draw_starts[d])..(end - draw_starts[d]) {
                    let ti = sel.triangle_index(j);
                    let [i0, i1, i2] = tris[ti as usize];
                    let v = [
                        cache.project(vp, m, pos, i0),
                        cache.project(vp, m, pos, i1),
                        cache.project(vp, m, pos, i2),
                    ];
                    emit([&v[0], &v[1], &v[2]], [i0, i1, i2], d, draw.first_item + ti as u64, out);
                }
            }
        }
        t = end;
    }
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: as above.
        unsafe { setup8::setup8_avx2(vp, draws, &mut batch, out) };
    }
}

/// Entries of [`VertexCache`] (a power of two).
const VERTEX_CACHE: usize = 64;

/// Projected vertices of the current index-list or range draw, direct-mapped by vertex index:
/// the triangles of a list share corners (a quad's two triangles share two, a strip's or a
/// fan's more), and a draw's indices are mostly runs of neighbours, so most shared corners are
/// projected once per draw instead of once per triangle, as a whole-mesh draw's are. Results
/// are unchanged: a projection is a function of the matrix and the position alone.
struct VertexCache {
    /// Vertex index held by each entry; `u32::MAX` (never an index: meshes have fewer than
    /// `u32::MAX` vertices) when empty.
    tags: [u32; VERTEX_CACHE],
    vertices: [ProjVertex; VERTEX_CACHE],
}

impl VertexCache {
    #[inline(always)]
    fn new() -> Self {
        Self {
            tags: [u32::MAX; VERTEX_CACHE],
            vertices: [ProjVertex::default(); VERTEX_CACHE],
        }
    }

    /// Empties the cache (a new draw, a new matrix).
    #[inline(always)]
    fn reset(&mut self) {
        self.tags = [u32::MAX; VERTEX_CACHE];
    }

    /// Vertex `i` of `positions` projected by `m`, from the cache when it holds it.
    #[inline(always)]
    fn project(&mut self, vp: &Viewport, m: &Mat4, positions: &[Vec3], i: u32) -> ProjVertex {
        let slot = i as usize & (VERTEX_CACHE - 1);
        if self.tags[slot] != i {
            self.tags[slot] = i;
            self.vertices[slot] = vp.project(m, positions[i as usize]);
        }
        self.vertices[slot]
    }
}

#[inline(always)]
fn setup_triangle(
    vp: &Viewport,
    v: [ProjVertex; 3],
    clip_from_object: &Mat4,
    corners: impl FnOnce() -> [Vec3; 3],
    item: ItemId,
    out: &mut impl SetupSink,
) {
    let or = v[0].code | v[1].code | v[2].code;
    if v[0].code & v[1].code & v[2].code & OUT_OF_VIEW != 0 || or & NOT_FINITE != 0 {
        return;
    }
    if or & NEEDS_CLIP != 0 {
        clip_and_setup(vp, clip_from_object, corners(), item, out);
        return;
    }
    setup_snapped(
        vp,
        [
            (v[0].x, v[0].y, v[0].z),
            (v[1].x, v[1].y, v[1].z),
            (v[2].x, v[2].y, v[2].z),
        ],
        item,
        out,
    );
}

/// Clips a triangle (object-space corners `p` under `clip_from_object`) against the near plane
/// and the guard band in homogeneous space and sets up the fan of the resulting polygon.
///
/// The clip coordinates are recomputed and clipped in f64: clipping subtracts those of corners
/// that may lie far apart (a ground plane reaching far past the near plane), and in f32 a new
/// corner's `w` could round to or below 0 and lose the whole triangle. The f64 products of the
/// f32 inputs are exact. A corner that no plane moves is still projected from its f32 clip
/// coordinates, which give it the bits every other path gives it, so that neighbours meet.
#[cold]
fn clip_and_setup(vp: &Viewport, clip_from_object: &Mat4, p: [Vec3; 3], item: ItemId, out: &mut impl SetupSink) {
    /// A corner of the clipped polygon: its clip coordinates in f64, and in f32 for a corner
    /// of the triangle itself.
    #[derive(Clone, Copy)]
    struct Corner {
        clip: DVec4,
        original: Option<Vec4>,
    }
    let (gx, gy) = (vp.guard_x as f64, vp.guard_y as f64);
    let planes = [
        DVec4::new(0.0, 0.0, -1.0, 1.0), // near: w - z >= 0
        DVec4::new(-1.0, 0.0, 0.0, gx),  // guard: g·w - x >= 0
        DVec4::new(1.0, 0.0, 0.0, gx),
        DVec4::new(0.0, -1.0, 0.0, gy),
        DVec4::new(0.0, 1.0, 0.0, gy),
    ];
    let m = clip_from_object.as_dmat4();
    let mut poly: Vec<Corner> = p
        .iter()
        .map(|&p| Corner {
            clip: m * p.as_dvec3().extend(1.0),
            original: Some(to_clip(clip_from_object, p)),
        })
        .collect();
    let mut next = Vec::with_capacity(9);
    for plane in planes {
        next.clear();
        for i in 0..poly.len() {
            let a = poly[i];
            let b = poly[(i + 1) % poly.len()];
            let da = plane.dot(a.clip);
            let db = plane.dot(b.clip);
            if da >= 0.0 {
                next.push(a);
            }
            if (da >= 0.0) != (db >= 0.0) {
                // Interpolate from the inside vertex, so a shared edge clips identically.
                let clip = if da >= 0.0 {
                    a.clip + (b.clip - a.clip) * (da / (da - db))
                } else {
                    b.clip + (a.clip - b.clip) * (db / (db - da))
                };
                next.push(Corner { clip, original: None });
            }
        }
        std::mem::swap(&mut poly, &mut next);
        if poly.len() < 3 {
            return;
        }
    }
    // A NaN w also fails this test.
    if !poly.iter().all(|c| c.clip.w > 0.0) {
        return;
    }
    // Clipped vertices lie on or inside every clip plane up to rounding: project them directly.
    let p: Vec<(i32, i32, f32)> = poly
        .iter()
        .map(|c| match c.original {
            // The expression of `Viewport::project_clip`, for the same bits.
            Some(c) if c.w > 0.0 => {
                let inv_w = 1.0 / c.w;
                let sx = (c.x * inv_w * 0.5 + 0.5) * vp.fwidth;
                let sy = (0.5 - c.y * inv_w * 0.5) * vp.fheight;
                (snap(sx), snap(sy), c.z * inv_w)
            }
            _ => {
                let c = c.clip;
                let sx = (c.x / c.w * 0.5 + 0.5) * vp.width as f64;
                let sy = (0.5 - c.y / c.w * 0.5) * vp.height as f64;
                (snap64(sx), snap64(sy), (c.z / c.w) as f32)
            }
        })
        .collect();
    if p.iter().any(|v| !v.2.is_finite()) || poly.iter().any(|c| !c.clip.is_finite()) {
        return;
    }
    let pieces = (1..p.len() - 1)
        .filter(|&i| setup_snapped(vp, [p[0], p[i], p[i + 1]], item, out))
        .count() as u32;
    // One triangle, counted once however many pieces it was cut into.
    out.uncount(pieces.saturating_sub(1));
}

/// Sets up a triangle from snapped vertices `(x, y, z)` and hands it to `out`; false when
/// there is nothing to scan (no pixel centre in its box, no area, facing away, beyond far).
#[inline(always)]
fn setup_snapped(vp: &Viewport, v: [(i32, i32, f32); 3], item: ItemId, out: &mut impl SetupSink) -> bool {
    let (x0, y0) = (v[0].0 as i64, v[0].1 as i64);
    let (mut x1, mut y1, mut z1) = (v[1].0 as i64, v[1].1 as i64, v[1].2);
    let (mut x2, mut y2, mut z2) = (v[2].0 as i64, v[2].1 as i64, v[2].2);
    let z0 = v[0].2;
    // Pixel box: centres (i + 1/2) inside [min, max] of the snapped corners.
    let minx = x0.min(x1).min(x2);
    let maxx = x0.max(x1).max(x2);
    let miny = y0.min(y1).min(y2);
    let maxy = y0.max(y1).max(y2);
    let px0 = ((minx - HALF + SUB - 1) >> SUBPIXEL_BITS).max(0);
    let px1 = ((maxx - HALF) >> SUBPIXEL_BITS).min(vp.width as i64 - 1);
    let py0 = ((miny - HALF + SUB - 1) >> SUBPIXEL_BITS).max(0);
    let py1 = ((maxy - HALF) >> SUBPIXEL_BITS).min(vp.height as i64 - 1);
    if px0 > px1 || py0 > py1 {
        return false;
    }
    out.will_touch(px0 as u32, py0 as u32, py1 > py0);
    let mut area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    if area == 0 {
        return false;
    }
    // On screen (y down) a counter-clockwise front face has negative area.
    if area > 0 && vp.cull_backfaces {
        return false;
    }
    let front = area < 0;
    if area < 0 {
        std::mem::swap(&mut x1, &mut x2);
        std::mem::swap(&mut y1, &mut y2);
        std::mem::swap(&mut z1, &mut z2);
        area = -area;
    }
    let zmin = min_f32(min_f32(z0, z1), z2);
    let zmax = max_f32(max_f32(z0, z1), z2);
    if zmax < vp.far_depth {
        return false;
    }
    // Depth plane in pixel units, relative to corner 0, computed in f64; anchored at the centre
    // of pixel (px0, py0) and stored in f32.
    let inv = 1.0 / (area as f64 / (SUB * SUB) as f64);
    let (fx1, fy1) = ((x1 - x0) as f64 / SUB as f64, (y1 - y0) as f64 / SUB as f64);
    let (fx2, fy2) = ((x2 - x0) as f64 / SUB as f64, (y2 - y0) as f64 / SUB as f64);
    let (dz1, dz2) = ((z1 - z0) as f64, (z2 - z0) as f64);
    let dzdx = (dz1 * fy2 - dz2 * fy1) * inv;
    let dzdy = (fx1 * dz2 - fx2 * dz1) * inv;
    let zc = z0 as f64
        + dzdx * ((px0 as f64 + 0.5) - x0 as f64 / SUB as f64)
        + dzdy * ((py0 as f64 + 0.5) - y0 as f64 / SUB as f64);
    out.push(
        vp,
        TriSetup {
            x: [x0 as i32, x1 as i32, x2 as i32],
            y: [y0 as i32, y1 as i32, y2 as i32],
            px0: px0 as u16,
            py0: py0 as u16,
            px1: px1 as u16,
            py1: py1 as u16,
            zc: zc as f32,
            dzdx: dzdx as f32,
            dzdy: dzdy as f32,
            zmin,
            zmax,
            extent: (((maxx - minx).max(maxy - miny) >> SUBPIXEL_BITS) + 1).min(u16::MAX as i64) as u16,
            front,
            item,
        },
    );
    true
}

/// The smaller of `a` and `b`, `b` when they compare equal or either is NaN: the rule of
/// `minps`, which the 8-lane setup uses (`f32::min` leaves the sign of a zero unspecified).
#[inline(always)]
fn min_f32(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// The larger of `a` and `b`, by the rule of `maxps` (see [`min_f32`]).
#[inline(always)]
fn max_f32(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// How [`scan_small`] finds the covered centres of a triangle it takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SmallCover {
    /// The edge functions as [`scan_triangle`] derives them: their values at the centre of
    /// pixel `(px0, py0)` and their steps per pixel right and down.
    Edges {
        row: [i32; 3],
        step_x: [i32; 3],
        step_y: [i32; 3],
    },
    /// For boxes of at most [`TINY`] × [`TINY`] pixels, the covered centres themselves as
    /// [`scan_small`]'s mask (bit `8·j + i` for centre `(i, j)` from the box's corner),
    /// derived in lanes by the 8-lane setup, which then reads no edge functions back.
    Mask(u32),
}

/// Where set-up triangles go: bins for the tile pass, or straight to the scan.
trait SetupSink {
    fn push(&mut self, vp: &Viewport, t: TriSetup);
    /// Whether [`Self::push_small`] uses the cover it is given: the 8-lane setup derives edge
    /// functions and masks only for sinks that do.
    const TAKES_EDGES: bool = false;
    /// [`Self::push`] for a triangle whose box the small scan takes, with its edge functions
    /// or, for a tiny box, its mask of covered centres already derived (by the 8-lane setup).
    #[inline(always)]
    fn push_small(&mut self, vp: &Viewport, t: TriSetup, _cover: SmallCover) {
        self.push(vp, t);
    }
    /// `n` triangles the 8-lane setup found to cover no pixel centre of a box of at most
    /// [`TINY`] × [`TINY`] pixels (only sinks that take edge functions get them): they count
    /// as set up; scanning them would write nothing.
    fn count_uncovered(&mut self, n: u32);
    /// Whether the 8-lane setup counts the lanes it hands over, a batch at a time, by
    /// [`Self::count_lanes`]: [`Self::push_lane`] and [`Self::push_small`] then count nothing
    /// (the pieces of a clipped lane still come through [`Self::push`], and count there).
    const COUNTS_LANES: bool = false;
    /// `n` lanes of a batch are about to be handed over (scanned), all within the inclusive
    /// pixel box `bounds` ([`EMPTY_RECT`] when `n` is 0); only called where `COUNTS_LANES`.
    #[inline(always)]
    fn count_lanes(&mut self, _n: u32, _bounds: [u32; 4]) {}
    /// [`Self::push`] for a lane of the 8-lane setup that the small scan does not take.
    #[inline(always)]
    fn push_lane(&mut self, vp: &Viewport, t: TriSetup) {
        self.push(vp, t);
    }
    /// `n` of the triangles pushed were further pieces of one that clipping cut: a triangle
    /// counts once as rasterized, however many pieces it was cut into.
    fn uncount(&mut self, n: u32);
    /// A hint: a triangle whose box starts at pixel `(x, y)` (and covers row `y + 1` if
    /// `two_rows`) is being set up, and a sink that scans at once may start fetching those
    /// pixels. The 8-lane setup hints all eight lanes, a lane without a triangle as (0, 0), so
    /// it must have no effect beyond the fetch.
    #[inline(always)]
    fn will_touch(&mut self, _x: u32, _y: u32, _two_rows: bool) {}
}

impl SetupSink for ChunkBins {
    #[inline(always)]
    fn count_uncovered(&mut self, n: u32) {
        self.rasterized += n as u64;
    }

    fn uncount(&mut self, n: u32) {
        self.rasterized -= n as u64;
    }

    #[inline(always)]
    fn push(&mut self, vp: &Viewport, t: TriSetup) {
        self.rasterized += 1;
        let r = self.records.len() as u32;
        let sh = vp.tile_shift;
        let (tx0, tx1, ty0, ty1) = (
            t.px0 as u32 >> sh,
            t.px1 as u32 >> sh,
            t.py0 as u32 >> sh,
            t.py1 as u32 >> sh,
        );
        self.records.push(t);
        if tx0 == tx1 && ty0 == ty1 {
            self.bins[(ty0 * vp.tiles_x + tx0) as usize].push(r);
            return;
        }
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                self.bins[(ty * vp.tiles_x + tx) as usize].push(r);
            }
        }
    }
}

/// Scans each triangle as soon as it is set up, over the whole frame: the single-threaded path,
/// where binning would only add work. Same scan, same results.
struct DirectSink<'a, const AVX2: bool> {
    target: &'a FrameTarget,
    rect: [u32; 4],
    mode: RasterMode,
    rasterized: u64,
    written: u64,
    /// Inclusive pixel box of everything scanned (empty while `dirty[0] > dirty[2]`).
    dirty: [u32; 4],
}

impl<const AVX2: bool> DirectSink<'_, AVX2> {
    /// Counts a triangle about to be scanned and grows the box of what was drawn by its box.
    #[inline(always)]
    fn count(&mut self, t: &TriSetup) {
        self.rasterized += 1;
        self.dirty = union_rect(self.dirty, [t.px0, t.py0, t.px1, t.py1].map(u32::from));
    }
}

impl<const AVX2: bool> SetupSink for DirectSink<'_, AVX2> {
    #[inline(always)]
    fn will_touch(&mut self, x: u32, y: u32, two_rows: bool) {
        // The rest of the setup (area, depth plane) overlaps with the fetch of pixels the scan
        // is about to test: first touches of the frame are this loop's main stall.
        let i = y as usize * self.target.width + x as usize;
        prefetch(self.target, i);
        // Without a branch (it mispredicts on tiny triangles): the first row again when the
        // box has one.
        prefetch(self.target, i + if two_rows { self.target.width } else { 0 });
    }

    #[inline(always)]
    fn push(&mut self, vp: &Viewport, t: TriSetup) {
        self.count(&t);
        self.push_lane(vp, t);
    }

    #[inline(always)]
    fn push_lane(&mut self, vp: &Viewport, t: TriSetup) {
        // SAFETY: a DirectSink is only made by `Isa::draw_direct`, whose caller guarantees that
        // no other thread touches the frame during the draw.
        self.written += unsafe { scan_triangle::<AVX2>(vp, &t, self.rect, self.target, self.mode) };
    }

    const TAKES_EDGES: bool = true;

    // Per batch in lanes, where counting each triangle was a load, compare and store of the
    // box's four sides per triangle.
    const COUNTS_LANES: bool = true;

    #[inline(always)]
    fn count_lanes(&mut self, n: u32, bounds: [u32; 4]) {
        self.rasterized += n as u64;
        self.dirty = union_rect(self.dirty, bounds);
    }

    #[inline(always)]
    fn count_uncovered(&mut self, n: u32) {
        // Counted like any other; nothing drawn, so the box of what was drawn stays.
        self.rasterized += n as u64;
    }

    fn uncount(&mut self, n: u32) {
        self.rasterized -= n as u64;
    }

    #[inline(always)]
    fn push_small(&mut self, vp: &Viewport, t: TriSetup, cover: SmallCover) {
        // Counted with its batch (`count_lanes`). The direct sink's rectangle is the whole
        // frame, which holds the box: `scan_triangle` would scan the box itself, small, from
        // these edge functions, or from the mask that the 8-lane setup formed from them.
        let rect = [t.px0 as u32, t.py0 as u32, t.px1 as u32, t.py1 as u32];
        // SAFETY: as in `push`.
        self.written += unsafe { scan_small::<AVX2>(vp, &t, rect, cover, self.target, self.mode) };
    }
}

/// Spans shorter than this are written pixel by pixel; longer ones by the vectorized loop.
const SHORT_SPAN: usize = 16;

/// Hints the processor to fetch the depth and item of pixel `i`; never faults, never changes
/// results.
#[inline(always)]
fn prefetch(target: &FrameTarget, i: usize) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint: it never faults, whatever the address.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(target.depth.wrapping_add(i) as *const i8);
        _mm_prefetch::<_MM_HINT_T0>(target.items.wrapping_add(i) as *const i8);
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (target, i);
}

/// Side of the block scanned without branches for small triangles.
const SMALL: u32 = 8;
/// Boxes of at most this many pixels a side have their mask of covered centres derived by the
/// 8-lane setup (in 32-bit lanes: the mask's bits reach `8·(TINY − 1) + TINY − 1`).
const TINY: u32 = 4;
const _: () = assert!(SMALL * (TINY - 1) + TINY <= 31);
/// Triangles whose snapped corners span fewer pixels than this (both axes) have their inside
/// masks computed in i32 lanes. The lanes reach up to 8 pixels past the box, so every point
/// evaluated lies within (56 + 8)·√2 pixels of a corner, and |E| <= (64·√2·256)² < 2^31.
const MASKED: u32 = 56;

/// Scans a box of at most `SMALL × SMALL` pixels: the inside mask of each row is formed
/// without branches in 32-bit lanes (tiny triangles make per-pixel branches mispredict), or
/// taken from a [`SmallCover::Mask`] the 8-lane setup formed already (anchored at the box's
/// corner, which is then `rect`'s), then only the covered pixels are depth-tested.
/// Bit-identical to the general scan.
///
/// 32 bits suffice: the caller checked that the snapped corners span fewer than [`MASKED`]
/// pixels, and every centre `p` of the 8 × 8 block lies within 8 pixels of the triangle's box,
/// so `|E(p)| = |(v1 - v0) × (p - v0)| <= (64·√2·256)² < 2^31` in 1/256 units.
///
/// # Safety
/// As [`scan_triangle`].
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn scan_small<const AVX2: bool>(
    vp: &Viewport,
    t: &TriSetup,
    rect: [u32; 4],
    cover: SmallCover,
    target: &FrameTarget,
    mode: RasterMode,
) -> u64 {
    let [x0, y0, x1, y1] = rect;
    let w = x1 - x0 + 1;
    let mask = match cover {
        SmallCover::Mask(tiny) => {
            debug_assert_eq!(
                (x0, y0),
                (t.px0 as u32, t.py0 as u32),
                "a lane mask is anchored at the box"
            );
            tiny as u64
        }
        SmallCover::Edges {
            mut row,
            step_x: sx,
            step_y,
        } => {
            let mut mask = 0u64;
            let valid = (1u64 << w) - 1;
            for j in 0..=(y1 - y0) {
                let bits = if AVX2 {
                    // SAFETY: the AVX2 instantiation only runs where `Isa::select` found AVX2.
                    unsafe { simd::row_mask_avx2(row, sx) }
                } else {
                    row_mask(row, sx)
                };
                mask |= (bits & valid) << (j * SMALL);
                row[0] += step_y[0];
                row[1] += step_y[1];
                row[2] += step_y[2];
            }
            mask
        }
    };
    // SAFETY: the mask's centres lie in the caller's rectangle, owned by this task.
    match mode {
        RasterMode::Full => unsafe { write_mask::<true>(vp, t, x0, y0, mask, target) },
        RasterMode::DepthOnly => unsafe { write_mask::<false>(vp, t, x0, y0, mask, target) },
    }
}

/// The per-pixel loop of [`scan_small`]: depth-tests and writes the fragments of `t` at the
/// centres of `mask` (bit `8·j + i` for pixel `(x0 + i, y0 + j)`), items too when `FULL`.
///
/// # Safety
/// Those pixels lie in the frame, and the caller owns them.
#[inline(always)]
unsafe fn write_mask<const FULL: bool>(
    vp: &Viewport,
    t: &TriSetup,
    x0: u32,
    y0: u32,
    mut mask: u64,
    target: &FrameTarget,
) -> u64 {
    let mode = if FULL { RasterMode::Full } else { RasterMode::DepthOnly };
    let mut written = 0;
    // In locals: the compiler cannot tell that the fragment writes leave `target` unchanged,
    // and would load these again for every fragment.
    let (depth, items, width) = (target.depth, target.items, target.width);
    while mask != 0 {
        let k = mask.trailing_zeros();
        mask &= mask - 1;
        let (x, y) = (x0 + k % SMALL, y0 + k / SMALL);
        let row_depth = row_depth(t, y);
        let z = depth_at(t, row_depth, x);
        if z >= vp.far_depth {
            let i = y as usize * width + x as usize;
            // SAFETY: forwarded from the caller.
            let (d, it) = unsafe { (&mut *depth.add(i), &mut *items.add(i)) };
            written += write_fragment(d, it, z, t.item, mode) as u64;
        }
    }
    written
}

/// Inside bits of the 8 pixel centres `i = 0..8` of a row whose edge functions at `i = 0` are
/// `row` and grow by `sx` per pixel: bit `i` set when all three are `>= 0`.
#[inline(always)]
fn row_mask(row: [i32; 3], sx: [i32; 3]) -> u64 {
    let mut bits = 0u64;
    for i in 0..SMALL as i32 {
        let e = (row[0] + sx[0] * i) | (row[1] + sx[1] * i) | (row[2] + sx[2] * i);
        bits |= ((e >= 0) as u64) << i;
    }
    bits
}

/// The one place with processor-specific intrinsics; each has a scalar twin above that the
/// tests hold bit-identical.
#[cfg(target_arch = "x86_64")]
mod simd {
    use std::arch::x86_64::*;

    /// [`super::row_mask`] in eight 32-bit lanes.
    ///
    /// # Safety
    /// The processor must support AVX2.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) unsafe fn row_mask_avx2(row: [i32; 3], sx: [i32; 3]) -> u64 {
        let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let e = |k: usize| {
            _mm256_add_epi32(
                _mm256_set1_epi32(row[k]),
                _mm256_mullo_epi32(_mm256_set1_epi32(sx[k]), lane),
            )
        };
        let or = _mm256_or_si256(_mm256_or_si256(e(0), e(1)), e(2));
        // Sign bit set means some edge function is negative: outside.
        (!(_mm256_movemask_ps(_mm256_castsi256_ps(or)) as u32) & 0xff) as u64
    }
}

/// Writes a covered fragment under the visibility rule (`keep_fragment`'s). The stored item is
/// read only on a depth tie (rare and predictable): where the fragment wins, its item line is
/// written without being waited for.
#[inline(always)]
fn write_fragment(d: &mut f32, it: &mut ItemId, z: f32, item: ItemId, mode: RasterMode) -> bool {
    let stored = *d;
    let keep = if z == stored {
        mode == RasterMode::Full && item < *it
    } else {
        z > stored
    };
    if keep {
        *d = z;
        if mode == RasterMode::Full {
            *it = item;
        }
    }
    keep
}

/// Writes the covered pixels `xa..xa + depth.len()` of one row: no coverage test left, so
/// the loop is branch-free and the compiler vectorizes it (8 lanes where AVX2 is enabled).
#[inline(always)]
fn write_span(
    vp: &Viewport,
    t: &TriSetup,
    row_depth: f32,
    xa: u32,
    depth: &mut [f32],
    items: &mut [ItemId],
    mode: RasterMode,
) -> u64 {
    let mut written = 0u32;
    let far = vp.far_depth;
    if depth.len() < SHORT_SPAN {
        // Short spans: per pixel, without reading the item buffer (see `write_fragment`).
        for (i, (d, it)) in depth.iter_mut().zip(items.iter_mut()).enumerate() {
            let z = depth_at(t, row_depth, xa + i as u32);
            if z >= far {
                written += write_fragment(d, it, z, t.item, mode) as u32;
            }
        }
        return written as u64;
    }
    match mode {
        RasterMode::Full => {
            for (i, (d, it)) in depth.iter_mut().zip(items.iter_mut()).enumerate() {
                let z = depth_at(t, row_depth, xa + i as u32);
                let keep = (z >= far) & ((z > *d) | ((z == *d) & (t.item < *it)));
                *d = if keep { z } else { *d };
                *it = if keep { t.item } else { *it };
                written += keep as u32;
            }
        }
        RasterMode::DepthOnly => {
            for (i, d) in depth.iter_mut().enumerate() {
                let z = depth_at(t, row_depth, xa + i as u32);
                let keep = (z >= far) & (z > *d);
                *d = if keep { z } else { *d };
                written += keep as u32;
            }
        }
    }
    written as u64
}

/// Depth of a triangle at the centre of pixel `(px0, y)`.
#[inline(always)]
fn row_depth(t: &TriSetup, y: u32) -> f32 {
    t.zc + t.dzdy * (y - t.py0 as u32) as f32
}

/// Depth of a triangle at the centre of pixel `(x, y)`: the one formula every path uses.
#[inline(always)]
fn depth_at(t: &TriSetup, row_depth: f32, x: u32) -> f32 {
    let z = row_depth + t.dzdx * (x - t.px0 as u32) as f32;
    let z = if z < t.zmin { t.zmin } else { z };
    if z > t.zmax {
        t.zmax
    } else {
        z
    }
}

/// The edge functions of `t` at the centre of pixel `(x0, y0)`, with their steps per pixel
/// right and down. Edge i runs from corner i to corner i+1; E(p) = A·px + B·py + C >= 0
/// inside, exactly, with the top-left rule folded in.
#[inline(always)]
fn edge_functions(t: &TriSetup, x0: u32, y0: u32) -> ([i64; 3], [i64; 3], [i64; 3]) {
    let (cx, cy) = (x0 as i64 * SUB + HALF, y0 as i64 * SUB + HALF);
    let mut row = [0i64; 3];
    let mut step_x = [0i64; 3];
    let mut step_y = [0i64; 3];
    for i in 0..3 {
        let j = (i + 1) % 3;
        let (xi, yi) = (t.x[i] as i64, t.y[i] as i64);
        let ea = yi - t.y[j] as i64;
        let eb = t.x[j] as i64 - xi;
        // Top-left rule: a centre on the edge counts only for left (A > 0) or top
        // (A = 0, B > 0) edges; other edges need E > 0, i.e. E - 1 >= 0 in integers.
        let bias = -(((ea < 0) | ((ea == 0) & (eb <= 0))) as i64);
        row[i] = ea * (cx - xi) + eb * (cy - yi) + bias;
        step_x[i] = ea * SUB;
        step_y[i] = eb * SUB;
    }
    (row, step_x, step_y)
}

/// Scans triangle `t` inside the inclusive pixel rectangle `rect`; returns fragments written.
///
/// # Safety
/// No other thread may access the pixels of `rect` in `target` during the call.
#[inline(always)]
unsafe fn scan_triangle<const AVX2: bool>(
    vp: &Viewport,
    t: &TriSetup,
    rect: [u32; 4],
    target: &FrameTarget,
    mode: RasterMode,
) -> u64 {
    let x0 = (t.px0 as u32).max(rect[0]);
    let y0 = (t.py0 as u32).max(rect[1]);
    let x1 = (t.px1 as u32).min(rect[2]);
    let y1 = (t.py1 as u32).min(rect[3]);
    if x0 > x1 || y0 > y1 {
        return 0;
    }
    let (mut row, step_x, step_y) = edge_functions(t, x0, y0);
    if (t.extent as u32) < MASKED && x1 - x0 < SMALL && y1 - y0 < SMALL {
        let edges = SmallCover::Edges {
            row: row.map(|e| e as i32),
            step_x: step_x.map(|e| e as i32),
            step_y: step_y.map(|e| e as i32),
        };
        // SAFETY: forwarded from the caller.
        return unsafe { scan_small::<AVX2>(vp, t, [x0, y0, x1, y1], edges, target, mode) };
    }
    let mut written = 0;
    let width = x1 - x0 + 1;
    // Boxes up to MASKED pixels keep edge functions within i32 (see `scan_small`): find each
    // row's span from 8-pixel inside masks. Larger ones solve for the span with divisions,
    // which only pay off on long rows.
    let masked = (t.extent as u32) < MASKED;
    let sx = [step_x[0] as i32, step_x[1] as i32, step_x[2] as i32];
    for y in y0..=y1 {
        let (mut lo, mut hi) = (0i64, width as i64 - 1);
        if masked {
            // The covered pixels of a row of a triangle are contiguous.
            let (mut first, mut last) = (i64::MAX, -1i64);
            let mut base = 0u32;
            while base < width {
                let r = [
                    row[0] as i32 + sx[0] * base as i32,
                    row[1] as i32 + sx[1] * base as i32,
                    row[2] as i32 + sx[2] * base as i32,
                ];
                let bits = if AVX2 {
                    // SAFETY: the AVX2 instantiation only runs where `Isa::select` found AVX2.
                    unsafe { simd::row_mask_avx2(r, sx) }
                } else {
                    row_mask(r, sx)
                };
                let bits = bits
                    & if width - base >= SMALL {
                        0xff
                    } else {
                        (1u64 << (width - base)) - 1
                    };
                if bits != 0 {
                    first = first.min(base as i64 + bits.trailing_zeros() as i64);
                    last = base as i64 + 63 - bits.leading_zeros() as i64;
                } else if last >= 0 {
                    break;
                }
                base += SMALL;
            }
            lo = first;
            hi = last;
        } else {
            for k in 0..3 {
                let (e, s) = (row[k], step_x[k]);
                if s > 0 {
                    lo = lo.max(if e >= 0 { 0 } else { (-e + s - 1) / s });
                } else if s < 0 {
                    hi = hi.min(if e < 0 { -1 } else { e / -s });
                } else if e < 0 {
                    hi = -1;
                }
            }
        }
        if lo <= hi {
            let row_depth = row_depth(t, y);
            let (xa, xb) = (x0 + lo as u32, x0 + hi as u32);
            let base = y as usize * target.width;
            // SAFETY: the span lies in `rect` (inside the frame), owned by this task.
            let (depth, items) = unsafe {
                (
                    std::slice::from_raw_parts_mut(target.depth.add(base + xa as usize), (xb - xa + 1) as usize),
                    std::slice::from_raw_parts_mut(target.items.add(base + xa as usize), (xb - xa + 1) as usize),
                )
            };
            written += write_span(vp, t, row_depth, xa, depth, items, mode);
        }
        row[0] += step_y[0];
        row[1] += step_y[1];
        row[2] += step_y[2];
    }
    written
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::{Affine3A, Camera};

    #[test]
    fn merge_keeps_the_rule_on_rows_with_clear_runs() {
        // Rows of every length around the run size, private pixels drawn in stretches (with
        // depth ties) between long clear ones, frame depths below the clear value among them,
        // against the rule applied pixel by pixel, on each instruction set the machine has.
        use crate::CLEAR_DEPTH;
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
        for n in (0..70).chain([333, 1000]) {
            for mode in [RasterMode::Full, RasterMode::DepthOnly] {
                let depths = [0.25f32, 0.5, 0.75];
                let frame_depths = [CLEAR_DEPTH, -0.0, -0.5, 0.25, 0.5, 0.75];
                let d: Vec<f32> = (0..n).map(|_| frame_depths[rng.random_range(0..6)]).collect();
                let it: Vec<ItemId> = (0..n).map(|_| rng.random_range(0..4)).collect();
                let mut drawn = rng.random_bool(0.5);
                let sd: Vec<f32> = (0..n)
                    .map(|_| {
                        drawn ^= rng.random_bool(0.05);
                        if drawn {
                            depths[rng.random_range(0..3)]
                        } else {
                            CLEAR_DEPTH
                        }
                    })
                    .collect();
                // Stale items under clear private depths must never win.
                let si: Vec<ItemId> = (0..n).map(|_| rng.random_range(0..4)).collect();
                for isa in [Isa::select(false), Isa::select(true)] {
                    let (mut got_d, mut got_it, mut got_sd) = (d.clone(), it.clone(), sd.clone());
                    isa.merge_row(&mut got_d, &mut got_it, &mut got_sd, &si, mode);
                    for x in 0..n {
                        let (mut want_d, mut want_it) = (d[x], it[x]);
                        if sd[x] != CLEAR_DEPTH {
                            let wins = match mode {
                                RasterMode::Full => sd[x] > d[x] || (sd[x] == d[x] && si[x] < it[x]),
                                RasterMode::DepthOnly => sd[x] > d[x],
                            };
                            if wins {
                                want_d = sd[x];
                                if mode == RasterMode::Full {
                                    want_it = si[x];
                                }
                            }
                        }
                        assert_eq!(
                            (got_d[x].to_bits(), got_it[x]),
                            (want_d.to_bits(), want_it),
                            "{isa:?}, {mode:?}, row {n}, pixel {x}"
                        );
                    }
                    assert!(
                        got_sd.iter().all(|&s| s == CLEAR_DEPTH),
                        "{isa:?}: private depths reset"
                    );
                }
            }
        }
    }

    /// An `n × n` grid of quads of side `side`, centred on the origin in the plane z = 0.
    fn grid(n: u32, side: f32) -> Mesh {
        let c = n as f32 * side / 2.0;
        let positions = (0..=n)
            .flat_map(|j| (0..=n).map(move |i| Vec3::new(i as f32 * side - c, j as f32 * side - c, 0.0)))
            .collect();
        let v = |i: u32, j: u32| j * (n + 1) + i;
        let triangles = (0..n)
            .flat_map(|j| {
                (0..n).flat_map(move |i| {
                    [
                        [v(i, j), v(i + 1, j), v(i, j + 1)],
                        [v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)],
                    ]
                })
            })
            .collect();
        Mesh::new(positions, triangles).unwrap()
    }

    /// On several threads, the automatic strategy draws fewer than
    /// [`SORT_LAST_MIN_TRIANGLES`] triangles directly on the calling thread, small or large,
    /// with the binned path's frame and counts; larger draws go sort-last over the pool, and
    /// forced strategies do what they say.
    #[test]
    fn small_draws_stay_on_the_calling_thread() {
        // One pixel is 2·10·tan 30° / 960 ≈ 0.012 units at the grid's distance.
        let view = View::new(Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO), 1280, 960).unwrap();
        let (tiny, large) = (grid(60, 0.012), grid(20, 0.5));
        let whole = |mesh| Draw {
            mesh,
            triangles: DrawTriangles::All,
            clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
            first_item: 0,
        };
        let many: Vec<u32> = (0..SORT_LAST_MIN_TRIANGLES as u32).map(|i| i % 7200).collect();
        let sort_last = Draw {
            triangles: DrawTriangles::List(&many),
            ..whole(&tiny)
        };
        let pass = |strategy, draws: &[Draw<'_>]| {
            let mut frame = Frame::new(1280, 960).unwrap();
            let mut r = Rasterizer::new(RasterConfig {
                threads: 2,
                strategy,
                ..RasterConfig::default()
            })
            .unwrap();
            let counts = r.draw(&view, &mut frame, draws, RasterMode::Full);
            let (on_caller, used) = r.last_pass.expect("the draw recorded its pass");
            (on_caller, used, counts)
        };
        for mesh in [&tiny, &large] {
            let draw = [whole(mesh)];
            let (on_caller, used, auto) = pass(Strategy::Auto, &draw);
            assert!(
                on_caller && used == Strategy::Direct,
                "{} triangles",
                mesh.triangle_count()
            );
            let (on_caller, used, binned) = pass(Strategy::Binned, &draw);
            assert!(!on_caller && used == Strategy::Binned);
            assert!(auto.fragments_written > 1000);
            assert_eq!(auto, binned, "{} triangles", mesh.triangle_count());
        }
        let (on_caller, used, _) = pass(Strategy::Auto, std::slice::from_ref(&sort_last));
        assert!(!on_caller && used == Strategy::SortLast, "large draws are shared");
        let (on_caller, used, _) = pass(Strategy::Direct, &[sort_last]);
        assert!(
            on_caller && used == Strategy::Direct,
            "forced direct stays on the caller"
        );
        // Frames: the same draw, automatic and binned.
        let draw = [whole(&tiny), whole(&large)];
        let mut frames = [Frame::new(1280, 960).unwrap(), Frame::new(1280, 960).unwrap()];
        for (f, strategy) in frames.iter_mut().zip([Strategy::Auto, Strategy::Binned]) {
            let mut r = Rasterizer::new(RasterConfig {
                threads: 2,
                strategy,
                ..RasterConfig::default()
            })
            .unwrap();
            r.draw(&view, f, &draw, RasterMode::Full);
        }
        assert_eq!(frames[0].items(), frames[1].items());
        assert!(frames[0]
            .depth()
            .iter()
            .zip(frames[1].depth())
            .all(|(x, y)| x.to_bits() == y.to_bits()));
    }

    /// A sort-last draw and a clear finish, with the frame and counts of one thread, while one
    /// of the rasterizer's two threads is blocked elsewhere: the other runs every job.
    #[test]
    fn draws_finish_while_a_pool_thread_is_blocked() {
        use std::sync::mpsc::channel;
        use std::time::Duration;
        let view = View::new(Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO), 320, 240)
            .expect("a valid 320 × 240 view");
        // 2 · 320² triangles: above the sort-last threshold.
        let mesh = grid(320, 0.03);
        assert!(mesh.triangle_count() >= SORT_LAST_MIN_TRIANGLES);
        let draw = [Draw {
            mesh: &mesh,
            triangles: DrawTriangles::All,
            clip_from_object: view.clip_from_object(&Affine3A::IDENTITY),
            first_item: 0,
        }];
        let drawn = |r: &mut Rasterizer| {
            let mut frame = Frame::new(320, 240).expect("a 320 × 240 frame");
            r.clear(&mut frame);
            let counts = r.draw(&view, &mut frame, &draw, RasterMode::Full);
            (counts, frame)
        };
        let (one, one_frame) = drawn(
            &mut Rasterizer::new(RasterConfig {
                threads: 1,
                ..RasterConfig::default()
            })
            .expect("a one-thread rasterizer"),
        );
        let mut r = Rasterizer::new(RasterConfig {
            threads: 2,
            ..RasterConfig::default()
        })
        .expect("a two-thread rasterizer");
        let (release, blocked) = channel::<()>();
        let (started, has_started) = channel();
        r.install(|| {
            rayon::spawn(move || {
                let _ = started.send(());
                let _ = blocked.recv();
            })
        });
        has_started.recv().expect("the blocking task started");
        let (done, finished) = channel();
        std::thread::scope(|s| {
            s.spawn(|| {
                let result = drawn(&mut r);
                let _ = done.send((result, r.last_pass));
            });
            let result = finished.recv_timeout(Duration::from_secs(120));
            // Release the blocked thread whatever happened, so that a hung draw ends too.
            drop(release);
            let ((counts, frame), pass) = result.expect("the draw finished with one pool thread blocked");
            assert_eq!(pass, Some((false, Strategy::SortLast)));
            assert_eq!(counts.triangles_rasterized, one.triangles_rasterized);
            assert!(counts.fragments_written > 1000);
            assert_eq!(frame.items(), one_frame.items());
            assert!(frame
                .depth()
                .iter()
                .zip(one_frame.depth())
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        });
    }

    /// Draws split into passes to bound the projected vertices give the frame and counts of
    /// one pass.
    #[test]
    fn passes_bounding_projected_vertices_change_nothing() {
        let (w, h) = (96, 64);
        let view = View::new(
            Camera::look_at(Vec3::new(0.5, 1.0, 6.0), Vec3::new(0.0, 0.0, 0.0)),
            w,
            h,
        )
        .unwrap();
        // A strip of 40 quads (82 vertices) and a fan (11 vertices), each instanced thrice,
        // with an index-list draw between them.
        let strip = Mesh::new(
            (0..=40)
                .flat_map(|i| {
                    [
                        Vec3::new(i as f32 * 0.1 - 2.0, 0.0, 0.0),
                        Vec3::new(i as f32 * 0.1 - 2.0, 1.0, 0.3),
                    ]
                })
                .collect(),
            (0..40u32)
                .flat_map(|i| [[2 * i, 2 * i + 2, 2 * i + 1], [2 * i + 1, 2 * i + 2, 2 * i + 3]])
                .collect(),
        )
        .unwrap();
        let fan = Mesh::new(
            std::iter::once(Vec3::ZERO)
                .chain((0..10).map(|i| {
                    let a = i as f32 * 0.6;
                    Vec3::new(a.cos(), a.sin(), 0.2)
                }))
                .collect(),
            (1..10u32).map(|i| [0, i, i + 1]).collect(),
        )
        .unwrap();
        let list = [1u32, 5, 7, 30, 31];
        let mut draws = Vec::new();
        for k in 0..3 {
            let m = Affine3A::from_translation(Vec3::new(0.0, k as f32 * 0.4 - 0.6, -(k as f32)));
            for (mesh, triangles) in [
                (&strip, DrawTriangles::All),
                (&fan, DrawTriangles::All),
                (&strip, DrawTriangles::List(&list)),
            ] {
                draws.push(Draw {
                    mesh,
                    triangles,
                    clip_from_object: view.clip_from_object(&m),
                    first_item: draws.len() as u64 * 1000,
                });
            }
        }
        // Two threads bin: the automatic strategy would draw these small passes directly.
        for (threads, strategy) in [(1, Strategy::Auto), (2, Strategy::Binned)] {
            let mut r = Rasterizer::new(RasterConfig {
                threads,
                strategy,
                ..RasterConfig::default()
            })
            .unwrap();
            let vp = Viewport::new(&view, r.config());
            let pool = r.pool.clone();
            let mut runs = Vec::new();
            // One pass; each whole mesh alone (82 > 50 goes alone, two fans fit); every draw alone.
            for max_vertices in [usize::MAX, 50, 1] {
                let mut f = Frame::new(w, h).unwrap();
                let single = threads == 1;
                let mut pass = || r.draw_in_passes(&vp, &mut f, &draws, RasterMode::Full, max_vertices, single);
                let counts = match pool.clone() {
                    Some(p) => p.install(pass),
                    None => pass(),
                };
                runs.push((counts, f));
            }
            assert!(runs[0].0.fragments_written > 500, "the view shows the draws");
            for (counts, f) in &runs[1..] {
                assert_eq!(counts.triangles_submitted, runs[0].0.triangles_submitted);
                assert_eq!(counts.triangles_rasterized, runs[0].0.triangles_rasterized);
                assert_eq!(f.items(), runs[0].1.items(), "{threads} threads");
                assert!(f
                    .depth()
                    .iter()
                    .zip(runs[0].1.depth())
                    .all(|(a, b)| a.to_bits() == b.to_bits()));
            }
        }
    }
}
