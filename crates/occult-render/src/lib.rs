//! # occult-render
//!
//! The renderers of occult, one module per paper, behind one [`Renderer`] trait, all drawing
//! through the same exact rasterizer (`occult-raster`) so that their frames can be compared
//! bit for bit, and all returning the same [`FrameStats`].
//!
//! | module | what |
//! | --- | --- |
//! | [`zbuffer`] | brute force: every triangle instance rasterized; the reference |
//! | [`frustum`] | hierarchical view-frustum culling only: the baseline the papers compare to |
//! | [`payoff`], [`direct`] | the culling renderers' guarantee: tests stop where they do not pay, frames are drawn as `frustum` draws them while culling loses |
//! | [`params`] | algorithm specs (`name:key=value,...`) and their parameters |
//! | [`walk`] | the one walk over the scene DAG every renderer uses (placements, counted frustum tests) |
//! | `occult_harness::compare` | runs several renderers over one camera path and measures them against each other |
//!
//! # Cancelling a frame, and its progress
//!
//! A caller that may give up a frame (the viewer, when the camera moves during a slow one)
//! puts a live [`FrameControl`] in [`RenderOptions`]' `raster.control` before building the
//! renderer, calls [`FrameControl::reset`] before each frame and [`FrameControl::cancel`] from
//! any thread to stop the frame in flight. The renderer checks at its batch boundaries: the
//! frame's start, every batch it hands the rasterizer (with a live control, draws
//! of over 2^20 triangles go in chunks of that size, checked between), the nodes of its own
//! hierarchy (`hzb`'s octree nodes, `oqgrid`'s query batches), `lzb`'s waves of 4,096 rays and
//! `rzb`'s work units of samples, and its end. A cancelled frame returns
//! [`RenderError::Cancelled`] (the frame's buffers then hold nothing to show) and changes
//! nothing the next frame reads: `hzb`'s visible list is conservative whatever it holds,
//! `oqgrid`'s and `nbuffer`'s lists and occluders stay last complete frame's, `lzb`'s rates and
//! `rzb`'s sample caches take nothing from it; the payoff measures none of it. The tests cancel
//! a frame at every check in turn and hold the frames after it identical to `zbuffer`'s.
//!
//! [`FrameControl::progress`] is the part of the frame done, 0 to 1, never decreasing within a
//! frame, 1 only once the frame is complete. What it counts:
//!
//! | renderer | progress |
//! | --- | --- |
//! | `zbuffer` | triangle instances submitted, of the scene's (in steps of 2^20) |
//! | `frustum`, and every culling renderer's direct frames | triangles submitted, of those the walk met, batch by batch |
//! | `hzb`, `oqgrid`, `nbuffer` | nothing until the frame is complete (their walks do not know their total ahead) |
//! | `lzb` | rays cast, of the unfinished pixels to cast, wave by wave |
//! | `rzb` | samples drawn, of those the box selection expects, unit by unit |
//!
//! Without a live control (the default) nothing is checked or reported, and draws are not
//! split.
//!
//! ```
//! use std::sync::Arc;
//! use occult_core::{Camera, Mesh, Scene, View, Vec3};
//! use occult_raster::Frame;
//! use occult_render::{Algorithm, RenderOptions};
//! let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]).expect("a valid mesh");
//! let scene = Arc::new(Scene::from_mesh("tri", mesh).expect("a valid scene"));
//! let eye = Vec3::new(0.3, 0.3, 2.0);
//! let view = View::new(Camera::look_at(eye, Vec3::new(0.3, 0.3, 0.0)), 32, 32).expect("a valid view");
//! let mut renderer = Algorithm::FRUSTUM.build(Arc::clone(&scene), &RenderOptions::default()).expect("frustum builds");
//! let mut frame = Frame::new(32, 32).expect("a valid frame size");
//! let stats = renderer.render(&view, &mut frame).expect("the frame renders");
//! assert_eq!(stats.triangles_rasterized, 1);
//! assert!(frame.covered_pixel_count() > 0);
//!
//! // The same, watched: cancelled, then complete.
//! use occult_render::{FrameControl, RenderError};
//! let control = FrameControl::new();
//! let mut options = RenderOptions::default();
//! options.raster.control = control.clone();
//! let mut renderer = Algorithm::FRUSTUM.build(scene, &options).expect("frustum builds");
//! control.cancel();
//! assert!(matches!(renderer.render(&view, &mut frame), Err(RenderError::Cancelled)));
//! control.reset();
//! renderer.render(&view, &mut frame).expect("an uncancelled frame renders");
//! assert_eq!(control.progress(), 1.0);
//! ```
#![deny(missing_docs)]

pub mod bands;
#[cfg(test)]
mod cancel_tests;
pub mod clusters;
pub mod columns;
pub mod direct;
pub mod frustum;
mod hash;
pub mod hzb;
pub mod list_choice;
pub mod lzb;
pub mod nbuffer;
mod nodes;
pub mod oqgrid;
pub mod params;
pub mod payoff;
mod runs;
pub mod rzb;
mod stats;
pub mod walk;
pub mod zbuffer;

use std::sync::Arc;
use std::time::Instant;

use occult_core::{Scene, View};
pub use occult_raster::FrameControl;
use occult_raster::{Frame, RasterConfig, RasterError, Rasterizer, ZPyramid};
pub use params::{AlgoSpec, ParamDoc, Params};
pub use stats::{Counters, FrameStats, FrameStatsMs, Phase, PhaseTimes};
use thiserror::Error;

/// Errors of renderers.
#[derive(Debug, Error)]
pub enum RenderError {
    /// A renderer parameter is out of range; the message names it.
    #[error("bad parameter: {0}")]
    BadParameter(String),
    /// The rasterizer refused (frame size, thread pool).
    #[error(transparent)]
    Raster(#[from] RasterError),
    /// The frame's size differs from the view's resolution.
    #[error("frame is {frame_width}x{frame_height} but the view is {view_width}x{view_height}")]
    FrameSizeMismatch {
        /// Frame width.
        frame_width: u32,
        /// Frame height.
        frame_height: u32,
        /// View width.
        view_width: u32,
        /// View height.
        view_height: u32,
    },
    /// Unknown algorithm name.
    #[error("unknown algorithm '{0}' (known: {known})", known = Algorithm::names().join(", "))]
    UnknownAlgorithm(String),
    /// More triangles lie in the view than one frame can draw (the message leaves the
    /// renderer's name to the caller, as the command line names it already).
    #[error("more than {limit} triangle instances lie in the view, more than one frame can draw; choose a view that sees less")]
    TooManyInView {
        /// The renderer that stopped.
        renderer: &'static str,
        /// The most triangles one frame draws.
        limit: u64,
    },
    /// A dynamic scene update that cannot be applied (the message names the entry and why).
    #[error("scene update: {0}")]
    Update(String),
    /// The frame was cancelled through its [`FrameControl`] ([`RenderOptions`]'
    /// `raster.control`) before it was complete: the frame's buffers hold no frame, and the
    /// renderer's next frame is drawn as if this one had not been asked for.
    #[error("frame cancelled")]
    Cancelled,
    /// A renderer spread over several ranks (processes or threads) failed on one of them, or
    /// their exchange did (the message names the rank and the cause).
    #[error("{0}")]
    Ranks(String),
}

/// Result with [`RenderError`].
pub type Result<T, E = RenderError> = std::result::Result<T, E>;

/// A visibility algorithm that renders frames of one scene.
///
/// Conservative renderers (everything except approximate ones) must produce frames
/// bit-identical to [`zbuffer::ZBuffer`] (DESIGN invariant 2).
pub trait Renderer: Send {
    /// Short name, as on the command line.
    fn name(&self) -> &'static str;
    /// Renders `view` into `frame` (cleared first), leaving depth and item ids; colors are
    /// resolved separately ([`occult_raster::shade`]).
    ///
    /// # Errors
    /// [`RenderError::FrameSizeMismatch`] when the frame does not match the view.
    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats>;
    /// Bytes held by the renderer's own structures, its rasterizers' scratch memory included
    /// (not the scene's, nor the frame it draws into).
    fn memory_bytes(&self) -> usize;
    /// Makes, ahead of the first frame, what frames of `width × height` need that a renderer
    /// would otherwise make in its first frames: buffers the size of a frame (the private
    /// frames of sort-last draws, workers' frames and depth pyramids), whose fresh pages cost
    /// a first frame milliseconds. Preparation, not a frame, then pays for them; callers that
    /// know the size call it after building. Frames do not change, and a frame of another size
    /// makes its own, as before. The default does nothing.
    ///
    /// # Errors
    /// Allocation refused.
    fn prepare(&mut self, width: u32, height: u32) -> Result<()> {
        let _ = (width, height);
        Ok(())
    }
    /// False for renderers whose frames are approximate (measured, not held identical).
    fn is_conservative(&self) -> bool {
        true
    }
}

/// Options every renderer takes.
#[derive(Clone, Default)]
pub struct RenderOptions {
    /// The rasterizer's configuration (threads, tiles, culling of back faces), and the
    /// [`FrameControl`] that cancels frames and reads their progress (see the crate doc).
    pub raster: RasterConfig,
    /// When set, [`AlgoSpec::build`] and [`Algorithm::build`] hand the scene, these options
    /// (without the hook) and the spec to it instead of building the renderer themselves: a
    /// renderer is then built around the one asked for. Sort-last rendering (`occult-mpi`)
    /// sets it so that every renderer a command builds (`compare`'s line-up and reference
    /// included) is built over this rank's part of the scene and composited across ranks,
    /// with no change to the commands.
    pub build_around: Option<BuildAround>,
}

/// Builds a renderer around the one a spec names; see [`RenderOptions::build_around`].
pub type BuildAround = Arc<dyn Fn(Arc<Scene>, &RenderOptions, &AlgoSpec) -> Result<Box<dyn Renderer>> + Send + Sync>;

impl std::fmt::Debug for RenderOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RenderOptions")
            .field("raster", &self.raster)
            .field("build_around", &self.build_around.as_ref().map(|_| "set"))
            .finish()
    }
}

impl RenderOptions {
    /// These options without [`RenderOptions::build_around`], and the hook, if set.
    fn split_hook(&self) -> (RenderOptions, Option<BuildAround>) {
        let inner = RenderOptions {
            raster: self.raster.clone(),
            build_around: None,
        };
        (inner, self.build_around.clone())
    }
}

/// Builds a renderer of a scene from options and its settings.
pub type BuildFn = fn(Arc<Scene>, &RenderOptions, &Params) -> Result<Box<dyn Renderer>>;

/// What the registry knows of one renderer: each module exports one as `INFO`.
pub struct AlgorithmInfo {
    /// Its command-line name.
    pub name: &'static str,
    /// One line: what it does and the paper it implements.
    pub summary: &'static str,
    /// Its settings, as `name:key=value` on the command line.
    pub params: &'static [ParamDoc],
    /// The names of the counters ([`FrameStats::counters`]) its frames may report, whichever
    /// its settings (a frame reports some only in some configurations); empty for renderers
    /// without counters of their own.
    pub counters: &'static [&'static str],
    /// Whether its frames are bit-identical to `zbuffer`'s (DESIGN invariant 2) or approximate
    /// (invariant 3).
    pub conservative: bool,
    /// Whether it draws a frame as bands of columns with `bands=N` ([`bands`]): it writes
    /// pixels only through the rasterizer, so that a band's view confines it to its columns.
    pub bands: bool,
    /// Builds it (the settings' keys are checked first).
    pub build: BuildFn,
}

/// Every renderer, in the order `all` lists them.
pub static ALGORITHMS: &[&AlgorithmInfo] = &[
    &zbuffer::INFO,
    &frustum::INFO,
    &hzb::INFO,
    &clusters::INFO,
    &oqgrid::INFO,
    &nbuffer::INFO,
    &lzb::INFO,
    &rzb::INFO,
];

/// A renderer, chosen at run time by name: a handle on its [`AlgorithmInfo`].
#[derive(Clone, Copy)]
pub struct Algorithm(&'static AlgorithmInfo);

impl PartialEq for Algorithm {
    fn eq(&self, other: &Self) -> bool {
        self.0.name == other.0.name
    }
}

impl Eq for Algorithm {}

impl std::hash::Hash for Algorithm {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.0.name.hash(state);
    }
}

impl std::fmt::Debug for Algorithm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Algorithm({})", self.0.name)
    }
}

impl Algorithm {
    /// [`zbuffer::ZBuffer`], the reference.
    pub const ZBUFFER: Algorithm = Algorithm(&zbuffer::INFO);
    /// [`frustum::FrustumCulling`], the baseline and the reference above brute-force sizes.
    pub const FRUSTUM: Algorithm = Algorithm(&frustum::INFO);

    /// Every registered algorithm.
    pub fn all() -> Vec<Algorithm> {
        ALGORITHMS.iter().map(|&i| Algorithm(i)).collect()
    }

    /// Names accepted by [`Algorithm::parse`].
    pub fn names() -> Vec<&'static str> {
        ALGORITHMS.iter().map(|i| i.name).collect()
    }

    /// The algorithm called `name`.
    ///
    /// # Errors
    /// [`RenderError::UnknownAlgorithm`].
    pub fn parse(name: &str) -> Result<Self> {
        ALGORITHMS
            .iter()
            .find(|i| i.name == name)
            .map(|&i| Algorithm(i))
            .ok_or_else(|| RenderError::UnknownAlgorithm(name.to_string()))
    }

    /// Its command-line name.
    pub fn name(self) -> &'static str {
        self.0.name
    }

    /// Its registry entry.
    pub fn info(self) -> &'static AlgorithmInfo {
        self.0
    }

    /// Its parameter keys, comma-separated, for messages (`none` when it has none).
    pub fn keys(self) -> String {
        let params = self.params();
        if params.is_empty() {
            return "none".into();
        }
        params.iter().map(|d| d.key).collect::<Vec<_>>().join(", ")
    }

    /// Its settings: its own, then `bands` ([`bands::BANDS_PARAM`]) where it takes it.
    pub fn params(self) -> Vec<ParamDoc> {
        let mut params = self.0.params.to_vec();
        if self.0.bands {
            params.push(bands::BANDS_PARAM);
        }
        params
    }

    /// The names of the counters ([`FrameStats::counters`]) it may report, whichever its
    /// settings (a frame reports some only in some configurations; [`bands`]' where it takes
    /// `bands`); empty for renderers without counters of their own.
    pub fn counter_names(self) -> Vec<&'static str> {
        let mut names = self.0.counters.to_vec();
        if self.0.bands {
            names.extend([bands::COUNTER, bands::IDLE]);
        }
        names
    }

    /// Builds the renderer for `scene` with default settings, doing its preprocessing (time
    /// it from outside).
    ///
    /// # Errors
    /// Bad options; see each renderer.
    pub fn build(self, scene: Arc<Scene>, options: &RenderOptions) -> Result<Box<dyn Renderer>> {
        AlgoSpec {
            algorithm: self,
            params: Params::new(self.0.name),
        }
        .build(scene, options)
    }
}

impl AlgoSpec {
    /// Builds the renderer for `scene` with these settings.
    ///
    /// # Errors
    /// Unknown keys, bad values; see each renderer.
    pub fn build(&self, scene: Arc<Scene>, options: &RenderOptions) -> Result<Box<dyn Renderer>> {
        self.check_keys()?;
        match options.split_hook() {
            (inner, Some(hook)) => hook(scene, &inner, self),
            (_, None) => match bands::bands(self)? {
                1 => (self.algorithm.0.build)(scene, options, &self.params),
                n => Ok(Box::new(bands::Bands::build(scene, options, self, n)?)),
            },
        }
    }
}

/// The rasterizer of a renderer of `scene`: `options`' configuration, with the buffer its
/// whole-mesh draws project vertices into reserved for the scene
/// ([`Rasterizer::reserve_vertices`]), so that its first large draw is not slowed by fresh
/// pages (preparation, not a frame, pays for them).
///
/// # Errors
/// Raster configuration errors; [`RasterError::OutOfMemory`] for the buffer.
pub(crate) fn scene_rasterizer(scene: &Scene, options: &RenderOptions) -> Result<Rasterizer> {
    let mut raster = Rasterizer::new(options.raster.clone())?;
    raster.reserve_vertices(scene.vertex_instance_count())?;
    Ok(raster)
}

/// [`Renderer::prepare`] for a rasterizer of `scene`: the private frames of its sort-last
/// draws ([`Rasterizer::reserve_frames`]), where memory allows (a speed-up, never an error:
/// draws make them or fall back as without).
pub(crate) fn prepare_raster(raster: &mut Rasterizer, scene: &Scene, width: u32, height: u32) {
    let _ = raster.reserve_frames(width, height, scene.item_count());
}

/// Makes `slot` a depth pyramid of `width × height` unless it holds one of that size
/// ([`Renderer::prepare`]).
///
/// # Errors
/// The pyramid refused.
pub(crate) fn sized_pyramid(slot: &mut Option<ZPyramid>, width: u32, height: u32) -> Result<()> {
    if !slot
        .as_ref()
        .is_some_and(|p| p.width() == width && p.height() == height)
    {
        *slot = Some(ZPyramid::new(width, height)?);
    }
    Ok(())
}

/// Rasterizes `draws` into `frame`, adding the time to [`Phase::Raster`] and the counts to
/// `stats`: the last step every renderer shares. Nothing once the frame is cancelled (the
/// renderer's next check, at the latest [`end_frame`], returns [`RenderError::Cancelled`]).
pub(crate) fn rasterize(
    raster: &mut occult_raster::Rasterizer,
    view: &View,
    frame: &mut Frame,
    draws: &[occult_raster::Draw<'_>],
    stats: &mut FrameStats,
) {
    rasterize_counted(raster, view, frame, draws, stats, None);
}

/// Triangles per draw call while a live [`FrameControl`] watches: the cancellation check and
/// progress report between two calls come at most this much work apart (tens of milliseconds
/// on two cores). Without a live control, draws go to the rasterizer in one call, as before.
const CONTROLLED_CHUNK_TRIANGLES: u64 = 1 << 20;

/// [`rasterize`], reporting progress when `progress` is `(triangles done before these draws,
/// triangles of the whole frame)`: the frame's fraction after each chunk of
/// [`CONTROLLED_CHUNK_TRIANGLES`] (with a live control, the draws go in such chunks, the
/// cancellation checked before each).
pub(crate) fn rasterize_counted(
    raster: &mut occult_raster::Rasterizer,
    view: &View,
    frame: &mut Frame,
    draws: &[occult_raster::Draw<'_>],
    stats: &mut FrameStats,
    progress: Option<(u64, u64)>,
) {
    let control = raster.config().control.clone();
    if !control.is_live() {
        draw_timed(raster, view, frame, draws, stats);
        return;
    }
    let mut done = progress.map_or(0, |p| p.0);
    let mut rest = draws;
    while !rest.is_empty() && !control.is_cancelled() {
        // Whole draws, up to a chunk.
        let (mut n, mut triangles) = (0, 0u64);
        while n < rest.len() && (n == 0 || triangles < CONTROLLED_CHUNK_TRIANGLES) {
            triangles += draw_triangle_count(&rest[n]);
            n += 1;
        }
        draw_timed(raster, view, frame, &rest[..n], stats);
        rest = &rest[n..];
        done += triangles;
        if let Some((_, total)) = progress {
            report_part(raster, done, total);
        }
    }
}

/// Where the draws of `raster` since the last call wrote a fragment
/// ([`occult_raster::Rasterizer::take_written`]), within `view`'s region: the only pixels a
/// depth structure over the frame (a pyramid) must be brought up to date over. `None` when
/// nothing was written there.
pub(crate) fn written_region(raster: &mut occult_raster::Rasterizer, view: &View) -> Option<occult_raster::PixelRect> {
    let (columns, rows) = (view.columns(), view.rows());
    let region = occult_raster::PixelRect {
        x0: columns.start,
        y0: rows.start,
        x1: columns.end,
        y1: rows.end,
    };
    raster.take_written()?.intersect(&region)
}

/// Draws `draws` in one call, adding the time to [`Phase::Raster`] and the counts to `stats`.
fn draw_timed(
    raster: &mut occult_raster::Rasterizer,
    view: &View,
    frame: &mut Frame,
    draws: &[occult_raster::Draw<'_>],
    stats: &mut FrameStats,
) {
    let t = Instant::now();
    let counts = raster.draw(view, frame, draws, occult_raster::RasterMode::Full);
    let spent = t.elapsed();
    stats.phases.add(Phase::Raster, spent);
    if counts.triangles_shared > 0 {
        stats.raster_shared += spent.mul_f64(counts.triangles_shared as f64 / counts.triangles_submitted as f64);
    }
    stats.add_raster(counts);
}

/// The triangles `draw` submits.
fn draw_triangle_count(draw: &occult_raster::Draw<'_>) -> u64 {
    draw.triangles.count(draw.mesh) as u64
}

/// [`RenderError::Cancelled`] when the frame drawn with `raster` was cancelled
/// ([`RasterConfig::control`]).
///
/// # Errors
/// [`RenderError::Cancelled`].
pub(crate) fn check_cancel(raster: &Rasterizer) -> Result<()> {
    if raster.config().control.is_cancelled() {
        return Err(RenderError::Cancelled);
    }
    Ok(())
}

/// Reports `done` of `total` units of the frame drawn with `raster` to its control: below 1
/// until [`end_frame`], so that 1 means a complete frame.
pub(crate) fn report_part(raster: &Rasterizer, done: u64, total: u64) {
    if total > 0 {
        raster
            .config()
            .control
            .report((done as f64 / total as f64).min(PART_MAX));
    }
}

/// The largest progress a frame reports before it is complete.
const PART_MAX: f64 = 0.999;

/// Ends a frame as every renderer does: [`RenderError::Cancelled`] if it was cancelled, else
/// the progress is 1 and `stats` are returned.
///
/// # Errors
/// [`RenderError::Cancelled`].
pub(crate) fn end_frame(raster: &Rasterizer, stats: FrameStats) -> Result<FrameStats> {
    check_cancel(raster)?;
    raster.config().control.report(1.0);
    Ok(stats)
}

/// Starts a frame as every renderer does: checks that `frame` matches `view`, clears it with
/// `raster`, and returns when the frame started, when the clear ended (where the timer of the
/// renderer's next phase starts) and statistics holding the clear's time ([`Phase::Clear`]).
///
/// # Errors
/// [`RenderError::FrameSizeMismatch`]; [`RenderError::Cancelled`] when the frame was cancelled
/// before it began.
pub(crate) fn begin_frame(
    raster: &mut Rasterizer,
    view: &View,
    frame: &mut Frame,
) -> Result<(Instant, Instant, FrameStats)> {
    check_frame(view, frame)?;
    check_cancel(raster)?;
    let start = Instant::now();
    let mut stats = FrameStats::default();
    raster.clear_region(
        frame,
        [
            view.columns().start,
            view.rows().start,
            view.columns().end,
            view.rows().end,
        ],
    );
    let cleared_at = Instant::now();
    stats.phases.add(Phase::Clear, cleared_at - start);
    Ok((start, cleared_at, stats))
}

/// Checks that `frame` matches `view`.
pub(crate) fn check_frame(view: &View, frame: &Frame) -> Result<()> {
    if frame.width() != view.width() || frame.height() != view.height() {
        return Err(RenderError::FrameSizeMismatch {
            frame_width: frame.width(),
            frame_height: frame.height(),
            view_width: view.width(),
            view_height: view.height(),
        });
    }
    Ok(())
}

/// Checks that two images that must be the same size are: `a_size` of `a` equals `b_size` of `b`
/// (both `(width, height)`, in pixels).
///
/// # Errors
/// [`RenderError::BadParameter`]: `"{context}: {a} is WxH but the {b} is WxH"`.
pub(crate) fn check_same_size(context: &str, a: &str, a_size: (u32, u32), b: &str, b_size: (u32, u32)) -> Result<()> {
    if a_size != b_size {
        return Err(RenderError::BadParameter(format!(
            "{context}: {a} is {}x{} but the {b} is {}x{}",
            a_size.0, a_size.1, b_size.0, b_size.1
        )));
    }
    Ok(())
}

/// For unit tests: a `g` × `g`-quad grid over the unit square at z = 0.
#[cfg(test)]
pub(crate) fn test_grid(g: u32) -> occult_core::Mesh {
    let n = g + 1;
    let positions = (0..n * n)
        .map(|i| occult_core::Vec3::new((i % n) as f32 / g as f32, (i / n) as f32 / g as f32, 0.0))
        .collect();
    let triangles = (0..g * g)
        .flat_map(|q| {
            let (x, y) = (q % g, q / g);
            let a = y * n + x;
            [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]
        })
        .collect();
    // A valid mesh by construction: every index is below (g + 1)^2.
    occult_core::Mesh::new(positions, triangles).expect("a grid is a valid mesh")
}

/// For unit tests: `rows` rows of `per_row` instances of a one-quad [`test_grid`], a unit
/// apart (two levels of groups: `rows * per_row` mesh instances, not walked to build).
#[cfg(test)]
pub(crate) fn test_quad_rows(rows: u32, per_row: u32) -> occult_core::Scene {
    use occult_core::{Affine3A, Instance, SceneBuilder, Vec3};
    let row_of = |n: u32, step: Vec3, child| -> Vec<Instance> {
        (0..n)
            .map(|i| Instance {
                parent_from_child: Affine3A::from_translation(step * i as f32),
                child,
            })
            .collect()
    };
    let mut b = SceneBuilder::new();
    let mesh = b.add_mesh("quad", test_grid(1)).expect("a mesh node");
    let row = b
        .add_group("row", row_of(per_row, Vec3::X, mesh))
        .expect("a group of the mesh");
    let all = b.add_group("all", row_of(rows, Vec3::Y, row)).expect("a group of rows");
    b.build(all).expect("a scene of groups")
}

/// For unit tests: a `width` x `height` view from `eye` towards `target`, with its
/// `clip_from_object` for objects placed at the world origin.
#[cfg(test)]
pub(crate) fn test_view(
    eye: occult_core::Vec3,
    target: occult_core::Vec3,
    width: u32,
    height: u32,
) -> (View, occult_core::Mat4) {
    let view = View::new(occult_core::Camera::look_at(eye, target), width, height).expect("a valid test view");
    let clip_from_object = view.clip_from_object(&occult_core::Affine3A::IDENTITY);
    (view, clip_from_object)
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::{Affine3A, Camera, Instance, Mesh, SceneBuilder, Vec3};

    /// `zbuffer`'s frame of `view` of `scene`: the reference a conservative renderer's frames
    /// are held to.
    pub(crate) fn zbuffer_frame(scene: &Arc<Scene>, view: &View) -> Frame {
        let mut f = Frame::new(view.width(), view.height()).expect("a frame of the view's size");
        crate::zbuffer::ZBuffer::new(scene.clone(), &RenderOptions::default())
            .expect("zbuffer builds")
            .render(view, &mut f)
            .expect("zbuffer renders the view");
        f
    }

    /// `f` run in a pool of each of `threads` threads, in turn.
    pub(crate) fn on_threads<T>(threads: &[usize], mut f: impl FnMut(&rayon::ThreadPool) -> T) -> Vec<T> {
        threads
            .iter()
            .map(|&n| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .expect("a small pool");
                f(&pool)
            })
            .collect()
    }

    /// A unit cube about the origin, 12 triangles wound outward.
    pub(crate) fn cube_mesh() -> Mesh {
        let p = [
            Vec3::new(-0.5, -0.5, -0.5),
            Vec3::new(0.5, -0.5, -0.5),
            Vec3::new(0.5, 0.5, -0.5),
            Vec3::new(-0.5, 0.5, -0.5),
            Vec3::new(-0.5, -0.5, 0.5),
            Vec3::new(0.5, -0.5, 0.5),
            Vec3::new(0.5, 0.5, 0.5),
            Vec3::new(-0.5, 0.5, 0.5),
        ];
        let t = vec![
            [0, 2, 1],
            [0, 3, 2],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [3, 7, 6],
            [3, 6, 2],
            [0, 4, 7],
            [0, 7, 3],
            [1, 2, 6],
            [1, 6, 5],
        ];
        Mesh::new(p.to_vec(), t).expect("a cube of in-range triangles is a valid mesh")
    }

    /// Unit cubes (one mesh, instanced) centred at `at` on a ground quad at y = -0.5 spanning
    /// `[x0, x1, z0, z1]`: the test scene of this crate's tests, where cubes hide each other
    /// and the ground.
    pub(crate) fn cubes_on_ground(ground: [f32; 4], at: impl IntoIterator<Item = Vec3>) -> Arc<Scene> {
        let mut b = SceneBuilder::new();
        let cube = b.add_mesh("cube", cube_mesh()).expect("a valid mesh adds");
        let [x0, x1, z0, z1] = ground;
        let ground = Mesh::new(
            vec![
                Vec3::new(x0, -0.5, z0),
                Vec3::new(x1, -0.5, z0),
                Vec3::new(x1, -0.5, z1),
                Vec3::new(x0, -0.5, z1),
            ],
            vec![[0, 2, 1], [0, 3, 2]],
        )
        .expect("a quad of in-range triangles is a valid mesh");
        let ground = b.add_mesh("ground", ground).expect("a valid mesh adds");
        let mut instances = vec![Instance {
            parent_from_child: Affine3A::IDENTITY,
            child: ground,
        }];
        instances.extend(at.into_iter().map(|at| Instance {
            parent_from_child: Affine3A::from_translation(at),
            child: cube,
        }));
        let root = b.add_group("cubes", instances).expect("a group of known nodes adds");
        Arc::new(b.build(root).expect("the ground has triangles and builds"))
    }

    /// Nine instanced boxes in a row along the view, on a ground quad: near boxes hide far ones.
    fn boxes() -> Arc<Scene> {
        cubes_on_ground(
            [-9.0, 9.0, -20.0, 2.0],
            (0..9).map(|i| Vec3::new(0.0, 0.0, -2.0 * i as f32)),
        )
    }

    #[test]
    fn every_counter_reported_is_declared() {
        let scene = boxes();
        let views: Vec<View> = [
            Vec3::new(0.0, 0.5, 4.0),
            Vec3::new(0.2, 0.6, 3.9),
            Vec3::new(6.0, 3.0, 4.0),
        ]
        .iter()
        .map(|&eye| {
            View::new(Camera::look_at(eye, Vec3::new(0.0, 0.0, -8.0)), 64, 48).expect("a 64x48 view of the boxes")
        })
        .collect();
        let specs = [
            "zbuffer",
            "frustum",
            "hzb",
            "hzb:parallel=hybrid,workers=2",
            "hzb:temporal=off,global=off",
            "lzb",
            "lzb:pvl=triangles,select=dynamic",
            "lzb:mode=naive,plane=static",
            "lzb:oor=off,coherence=off,caster=octree",
            "oqgrid",
            "oqgrid:grid=uniform,queries=off",
            "oqgrid:parallel=columns,strips=3",
            "hzb:parallel=columns",
            "nbuffer",
            "nbuffer:test=query,hierarchy=flat",
            "rzb",
            "rzb:cache=on,orientation=2",
            "rzb:eps=auto,max_samples=10",
            "hzb:bands=2",
            "clusters:bands=3,payoff=off",
        ];
        let mut options = RenderOptions::default();
        options.raster.threads = 1;
        for spec in specs {
            let spec = AlgoSpec::parse(spec).expect("every listed spec parses");
            let declared = spec.algorithm.counter_names();
            let mut renderer = spec
                .build(Arc::clone(&scene), &options)
                .expect("every listed spec builds for the boxes");
            let mut frame = Frame::new(64, 48).expect("a 64x48 frame");
            for view in &views {
                let stats = renderer
                    .render(view, &mut frame)
                    .expect("every listed renderer renders the boxes");
                for (name, _) in &stats.counters.0 {
                    assert!(declared.contains(name), "{spec}: counter {name} is not declared");
                }
            }
        }
    }
}
