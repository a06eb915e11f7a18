//! The comparison harness: several renderers, one scene, one camera path, one process.
//!
//! [`compare`] builds each requested renderer (timing its preprocessing), then renders every
//! view with every renderer **interleaved frame by frame** (view 0 with all renderers, then
//! view 1, ...; the order of the renderers rotates from frame to frame), so that machine noise,
//! thermal state and cache warmth hit all of them alike. Each frame of each renderer is compared
//! with the reference renderer's frame of the same view:
//!
//! - **reference** ([`Reference`]): by default `zbuffer` whenever the scene has at most
//!   [`MAX_BRUTE_FORCE_ITEMS`](crate::zbuffer::MAX_BRUTE_FORCE_ITEMS) triangle instances,
//!   otherwise `frustum` (the conservative renderer that scales); or any conservative renderer
//!   named by the caller; or none, for scenes even `frustum` cannot render in useful time
//!   (10^14 triangles): then no frame is checked and there is no oracle. The reference is always
//!   rendered and reported, requested or not ([`RendererReport::requested`] says which), so a
//!   report always holds the renderer its numbers are relative to.
//! - **identical**: depth (bit for bit) and item ids equal to the reference's
//!   ([`Frame::same_visibility`]); DESIGN invariant 2 demands it of conservative renderers.
//! - **error** of a frame that is not identical: share of covered pixels (covered in either
//!   frame) whose item differs, and the PSNR of the shaded colors (DESIGN invariant 3).
//! - **oracle** (DESIGN, "Measurement"): the time to clear a frame and rasterize exactly the
//!   triangles visible in the reference frame (its item buffer), as mesh-instance draws of
//!   triangle lists. It is the lower bound a culling renderer could reach with a perfect
//!   visibility oracle; each renderer's mean time is reported as a ratio to it
//!   ([`RendererReport::vs_oracle`]). The oracle's frame is checked against the reference too:
//!   rasterizing only the winners of every pixel must reproduce the frame exactly.
//!
//! - **image measures** per view ([`ImageMeasures`]): pixels covered in the reference frame
//!   (without a reference: in the first renderer's), and on request the image complexity of
//!   Han & Zeiger, the screen area of every triangle in the view, hidden or not, from which the
//!   depth complexity (image complexity over covered pixels) follows.
//!
//! - **memory**: each renderer's own structures ([`Renderer::memory_bytes`]) after its build and
//!   after its last frame, and the peak resident set size of the process while it was built and
//!   while it rendered ([`RendererReport::peak_rss_bytes`]): on Linux the kernel's high-water
//!   mark is reset (`5` written to `/proc/self/clear_refs`) before the build and before each of
//!   its frames, and read (`VmHWM` of `/proc/self/status`) after each. It is the whole process's
//!   memory: the scene, the harness's frames, and, because renderers are built one after another
//!   and then render interleaved, every renderer built before it (during its build) or all of
//!   them (during its frames). What tells renderers apart is what their build and frames add.
//!
//! Times are wall-clock times of whole [`Renderer::render`] calls (clearing included), in
//! milliseconds; the memory readings lie outside the timed calls. Nothing here reads or writes
//! files or prints, except the `/proc/self` files above where they exist (Linux); the CLI
//! writes the report out.
//!
//! Cost: every renderer's frames plus one shading pass per non-identical frame; one frame
//! buffer (16 bytes a pixel) per renderer plus two.
//!
//! ```
//! use std::sync::Arc;
//! use occult_core::{Camera, Mesh, Scene, Vec3};
//! use occult_render::compare::{compare, CompareConfig};
//! use occult_render::Algorithm;
//! let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]).unwrap();
//! let scene = Arc::new(Scene::from_mesh("tri", mesh).unwrap());
//! let cameras = [Camera::look_at(Vec3::new(0.3, 0.3, 2.0), Vec3::new(0.3, 0.3, 0.0))];
//! let config = CompareConfig::new(vec![Algorithm::FRUSTUM], 32, 32);
//! let report = compare(scene, &cameras, &config, &mut |_| {}).unwrap();
//! assert_eq!(report.reference.as_deref(), Some("zbuffer")); // rendered although not requested
//! assert_eq!(report.renderer("frustum").unwrap().frames_identical, Some(1));
//! assert_eq!(report.oracle.as_ref().unwrap().triangles_visible, [1]);
//! ```
//!
//! Deviation from the harness first sketched (`views: &[View]`): it takes cameras and one
//! resolution ([`CompareConfig::width`], [`CompareConfig::height`]), since every frame of a
//! comparison must have the same size and camera paths yield cameras.

use std::collections::HashSet;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use occult_core::{
    compose, Affine3A, Camera, Containment, CoreError, ItemId, Mat4, Mesh, NodeId, NodeKind, Scene, Vec4, View, NO_ITEM,
};
use occult_raster::{shade, Draw, DrawTriangles, Frame, RasterError, RasterMode, Rasterizer};
use rayon::prelude::*;
use serde::Serialize;
use thiserror::Error;

use crate::zbuffer::MAX_BRUTE_FORCE_ITEMS;
use crate::{AlgoSpec, Algorithm, Counters, FrameStats, Phase, RenderError, RenderOptions, Renderer};

/// Errors of [`compare`].
#[derive(Debug, Error)]
pub enum CompareError {
    /// No camera to render.
    #[error("the camera path is empty")]
    NoViews,
    /// No algorithm requested.
    #[error("no algorithm to compare")]
    NoAlgorithms,
    /// A camera of the path (numbered from 0) cannot form a view at the requested size.
    #[error("view {view_index}: {source}")]
    BadView {
        /// Position of the camera in the path.
        view_index: usize,
        /// Why.
        source: CoreError,
    },
    /// A renderer could not be built.
    #[error("building {algorithm}: {source}")]
    Build {
        /// The renderer's name.
        algorithm: String,
        /// Why.
        source: RenderError,
    },
    /// A renderer failed on a frame.
    #[error("{algorithm}, frame {view_index}: {source}")]
    Render {
        /// The renderer's name.
        algorithm: String,
        /// The frame.
        view_index: usize,
        /// Why.
        source: RenderError,
    },
    /// The reference asked for cannot be one: not conservative, or `zbuffer` on a scene too
    /// large for brute force.
    #[error("reference {reference}: {reason}")]
    BadReference {
        /// The renderer named as reference.
        reference: String,
        /// Why it cannot be.
        reason: String,
    },
    /// Frames or the oracle's rasterizer could not be made.
    #[error(transparent)]
    Raster(#[from] RasterError),
}

/// Result with [`CompareError`].
pub type Result<T, E = CompareError> = std::result::Result<T, E>;

/// What to compare and how.
#[derive(Clone, Debug)]
pub struct CompareConfig {
    /// Renderers to compare, in report order (duplicate labels are ignored); several
    /// configurations of one algorithm are distinct renderers, named by their
    /// [`AlgoSpec::label`]. The reference is added when missing (see the module doc).
    pub algorithms: Vec<AlgoSpec>,
    /// Options every renderer is built with (the same for all, as comparisons require).
    pub options: RenderOptions,
    /// Frame width in pixels.
    pub width: u32,
    /// Frame height in pixels.
    pub height: u32,
    /// What frames are checked against.
    pub reference: Reference,
    /// Also measure each view's image complexity ([`ImageMeasures::projected_pixels`]): one
    /// more pass over every triangle of the scene per view, not timed.
    pub image_complexity: bool,
}

/// The renderer whose frames the others must reproduce (module doc).
#[derive(Clone, Debug, Default)]
pub enum Reference {
    /// `zbuffer`, or `frustum` on scenes above [`MAX_BRUTE_FORCE_ITEMS`].
    #[default]
    Auto,
    /// This renderer, which must be conservative.
    Spec(AlgoSpec),
    /// None: frames are not checked and there is no oracle.
    None,
}

impl CompareConfig {
    /// Compares `algorithms` (plain [`Algorithm`]s or [`AlgoSpec`]s) at `width × height` with
    /// default options.
    pub fn new<A: Into<AlgoSpec>>(algorithms: impl IntoIterator<Item = A>, width: u32, height: u32) -> Self {
        Self {
            algorithms: algorithms.into_iter().map(Into::into).collect(),
            options: RenderOptions::default(),
            width,
            height,
            reference: Reference::Auto,
            image_complexity: false,
        }
    }
}

/// Progress events, for progress bars.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CompareProgress<'a> {
    /// About to build renderer `index` of `count`.
    Building {
        /// The renderer's label.
        label: &'a str,
        /// Its position, from 0.
        index: usize,
        /// Renderers to build.
        count: usize,
    },
    /// A renderer was built, in `prepare_ms` milliseconds.
    Built {
        /// The renderer's label.
        label: &'a str,
        /// Its preprocessing time.
        prepare_ms: f64,
    },
    /// View `index` of `count` was rendered by every renderer and compared.
    Frame {
        /// The view, from 0.
        index: usize,
        /// Views in all.
        count: usize,
    },
}

/// One frame of one renderer.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FrameRecord {
    /// Wall time of the render call, ms.
    pub time_ms: f64,
    /// Triangle instances handed to the rasterizer.
    pub triangles_submitted: u64,
    /// Triangles rasterized (see [`FrameStats::triangles_rasterized`]).
    pub triangles_rasterized: u64,
    /// Bit-identical to the reference frame (depth and items); false when there is no
    /// reference.
    pub identical: bool,
    /// When not identical: share of pixels covered in either frame whose item differs, in
    /// `[0, 1]`. `None` when identical.
    pub item_error: Option<f64>,
    /// When not identical: PSNR of the shaded color against the reference's, dB (`None` when
    /// identical, i.e. infinite).
    pub psnr_db: Option<f64>,
    /// The renderer's own counters ([`FrameStats::counters`]).
    pub counters: Counters,
}

/// Mean of a time phase over the frames.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PhaseMean {
    /// The phase.
    pub phase: Phase,
    /// Mean time per frame, ms (frames where the phase did not occur count as 0).
    pub mean_ms: f64,
}

/// The [`FrameStats`] counters, averaged over frames.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MeanStats {
    /// Mean triangles submitted.
    pub triangles_submitted: f64,
    /// Mean triangles rasterized.
    pub triangles_rasterized: f64,
    /// Mean fragments written.
    pub fragments_written: f64,
    /// Mean hierarchy nodes visited.
    pub nodes_visited: f64,
    /// Mean boxes tested.
    pub boxes_tested: f64,
    /// Mean boxes culled.
    pub boxes_culled: f64,
    /// Mean rectangles tested.
    pub rects_tested: f64,
    /// Mean rectangles culled.
    pub rects_culled: f64,
    /// Mean rays cast.
    pub rays_cast: f64,
    /// Mean samples drawn.
    pub samples_drawn: f64,
    /// Mean of each of the renderer's own counters ([`FrameStats::counters`]), by name.
    pub counters: std::collections::BTreeMap<&'static str, f64>,
    /// Mean of the renderer's own `FrameStats::total`, ms.
    pub total_ms: f64,
}

/// Summary of a series of frame times.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TimeSummary {
    /// Mean, ms.
    pub mean_ms: f64,
    /// Median, ms.
    pub median_ms: f64,
    /// 95th percentile (nearest rank), ms.
    pub p95_ms: f64,
    /// Fastest frame, ms.
    pub min_ms: f64,
    /// Slowest frame, ms.
    pub max_ms: f64,
}

impl TimeSummary {
    /// Summarises `times_ms` (all zero when empty).
    pub fn of(times_ms: &[f64]) -> Self {
        if times_ms.is_empty() {
            return Self::default();
        }
        let mut sorted = times_ms.to_vec();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        let rank = |q: f64| sorted[((q * n as f64).ceil() as usize).clamp(1, n) - 1];
        Self {
            mean_ms: sorted.iter().sum::<f64>() / n as f64,
            median_ms: rank(0.5),
            p95_ms: rank(0.95),
            min_ms: sorted[0],
            max_ms: sorted[n - 1],
        }
    }
}

/// The measurements of one renderer.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RendererReport {
    /// Command-line name.
    pub name: String,
    /// True for the reference renderer.
    pub is_reference: bool,
    /// False when it was rendered only because it is the reference.
    pub requested: bool,
    /// [`Renderer::is_conservative`]: its frames must be identical to the reference's.
    pub conservative: bool,
    /// Frames rendered.
    pub frames: usize,
    /// Frames bit-identical to the reference's; `None` when there is no reference (nothing was
    /// checked).
    pub frames_identical: Option<usize>,
    /// Mean frame time, ms.
    pub mean_ms: f64,
    /// 95th percentile frame time, ms.
    pub p95_ms: f64,
    /// Median, min and max too.
    pub time: TimeSummary,
    /// `zbuffer`'s mean time over this renderer's, measured in the same run (> 1: faster);
    /// `None` when `zbuffer` is not in the report.
    pub speedup_vs_zbuffer: Option<f64>,
    /// This renderer's mean time over the oracle's (>= 1 in practice; the lower the better);
    /// `None` when the oracle's mean time is zero.
    pub vs_oracle: Option<f64>,
    /// Mean triangles rasterized per frame.
    pub triangles_rasterized: f64,
    /// Triangles rasterized over all frames.
    pub triangles_rasterized_total: u64,
    /// Mean exactly visible triangles per frame (from the reference's item buffer; the same
    /// for every renderer, repeated here to read beside `triangles_rasterized`).
    pub triangles_visible: f64,
    /// Exactly visible triangles summed over frames.
    pub triangles_visible_total: u64,
    /// Preprocessing ([`Algorithm::build`]) time, ms.
    pub prepare_ms: f64,
    /// [`Renderer::memory_bytes`] after the last frame (its own structures, not the scene's).
    pub memory_bytes: usize,
    /// [`Renderer::memory_bytes`] right after it was built.
    pub memory_bytes_after_build: usize,
    /// Peak resident set size of the whole process while this renderer was built and while it
    /// rendered its frames, bytes (module doc: the scene and the other renderers' structures
    /// are included). `None` where it cannot be measured: not Linux, or the kernel's
    /// high-water mark could not be reset.
    pub peak_rss_bytes: Option<u64>,
    /// Mean share of differing covered pixels over all frames (0 for identical frames).
    pub mean_item_error: f64,
    /// Largest per-frame share of differing covered pixels.
    pub max_item_error: f64,
    /// Lowest per-frame color PSNR, dB; `None` when every frame is identical.
    pub min_psnr_db: Option<f64>,
    /// Mean time per phase, ms, in the order the renderer reports phases.
    pub phases: Vec<PhaseMean>,
    /// Mean counters.
    pub stats: MeanStats,
    /// Every frame, in path order.
    pub per_frame: Vec<FrameRecord>,
}

/// The oracle: rasterizing exactly the visible triangles.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OracleReport {
    /// Mean time, ms.
    pub mean_ms: f64,
    /// 95th percentile, ms.
    pub p95_ms: f64,
    /// Median, min and max too.
    pub time: TimeSummary,
    /// Frames whose oracle frame equals the reference's (should be all).
    pub frames_identical: usize,
    /// Time per frame, ms.
    pub per_frame_ms: Vec<f64>,
    /// Exactly visible triangles per frame.
    pub triangles_visible: Vec<u64>,
}

/// What each view's image holds, independent of the renderers.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ImageMeasures {
    /// Whose frames the measures were read from: the reference, or the first renderer when
    /// there is none.
    pub measured_on: String,
    /// Pixels covered by a triangle, per view.
    pub covered_pixels: Vec<u64>,
    /// Distinct triangles seen in the frame, per view (the exactly visible set when measured
    /// on a conservative renderer).
    pub triangles_visible: Vec<u64>,
    /// Image complexity |Ω| (Han & Zeiger §I): the summed screen area, in pixels, of every
    /// triangle instance of the scene clipped to the view frustum (near, far and the four
    /// sides), hidden or not, back faces included, per view; `None` unless asked for
    /// ([`CompareConfig::image_complexity`]).
    pub projected_pixels: Option<Vec<f64>>,
}

impl ImageMeasures {
    /// Mean depth complexity: image complexity over covered pixels, per view, averaged;
    /// `None` without the image complexity.
    pub fn mean_depth_complexity(&self) -> Option<f64> {
        let p = self.projected_pixels.as_ref()?;
        let per_view: Vec<f64> = p
            .iter()
            .zip(&self.covered_pixels)
            .map(|(&a, &c)| if c == 0 { 0.0 } else { a / c as f64 })
            .collect();
        Some(mean(per_view.iter().copied(), per_view.len()))
    }

    /// Mean covered pixels per view.
    pub fn mean_covered_pixels(&self) -> f64 {
        mean(self.covered_pixels.iter().map(|&c| c as f64), self.covered_pixels.len())
    }
}

/// A renderer that was requested but could not take part, and why.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Skipped {
    /// Its name.
    pub name: String,
    /// Why.
    pub reason: String,
}

/// Everything [`compare`] measured. Serializes to JSON (see the CLI's `compare --json`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CompareReport {
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// Views rendered by each renderer.
    pub frames: usize,
    /// Triangle instances in the scene.
    pub scene_triangles: u64,
    /// Bytes held by the scene ([`Scene::memory_bytes`]).
    pub scene_memory_bytes: usize,
    /// Rasterizer worker threads.
    pub threads: usize,
    /// Name of the reference renderer; `None` when frames were not checked.
    pub reference: Option<String>,
    /// Why that one.
    pub reference_note: String,
    /// The oracle; `None` without a reference.
    pub oracle: Option<OracleReport>,
    /// Per-view measures of the image.
    pub image: ImageMeasures,
    /// The renderers, requested order, the reference first when it was not requested.
    pub renderers: Vec<RendererReport>,
    /// Requested renderers left out (zbuffer on a scene too large for brute force).
    pub skipped: Vec<Skipped>,
    /// Peak resident set size of the whole process (VmHWM), bytes: process-wide, covering the
    /// scene, every renderer and everything else the process did; `None` where unavailable.
    pub process_peak_rss_bytes: Option<u64>,
}

impl CompareReport {
    /// The report of the renderer called `name`.
    pub fn renderer(&self, name: &str) -> Option<&RendererReport> {
        self.renderers.iter().find(|r| r.name == name)
    }
}

/// Per-renderer state during the run.
struct Contestant {
    spec: AlgoSpec,
    label: String,
    requested: bool,
    renderer: Box<dyn Renderer>,
    frame: Frame,
    prepare_ms: f64,
    memory_bytes_after_build: usize,
    /// Highest process high-water mark over its build and frames; `None` once one could not
    /// be measured.
    peak_rss_bytes: Option<u64>,
    records: Vec<FrameRecord>,
    stats: Vec<FrameStats>,
}

/// Runs every renderer of `config` over `cameras` on `scene` and measures them (module doc).
/// `progress` is called as renderers are built and frames are done.
///
/// # Errors
/// [`CompareError::NoViews`], [`CompareError::NoAlgorithms`], [`CompareError::BadView`] for a
/// degenerate camera or a bad resolution, [`CompareError::Build`] and
/// [`CompareError::Render`] when a renderer fails (a requested `zbuffer` on a scene above
/// [`MAX_BRUTE_FORCE_ITEMS`] is skipped and listed in [`CompareReport::skipped`] instead).
pub fn compare(
    scene: Arc<Scene>,
    cameras: &[Camera],
    config: &CompareConfig,
    progress: &mut dyn FnMut(CompareProgress),
) -> Result<CompareReport> {
    if cameras.is_empty() {
        return Err(CompareError::NoViews);
    }
    if config.algorithms.is_empty() {
        return Err(CompareError::NoAlgorithms);
    }
    let views = cameras
        .iter()
        .enumerate()
        .map(|(view_index, c)| {
            View::new(*c, config.width, config.height).map_err(|source| CompareError::BadView { view_index, source })
        })
        .collect::<Result<Vec<_>>>()?;

    // Choose the reference and the line-up.
    let brute_force_ok = scene.item_count() <= MAX_BRUTE_FORCE_ITEMS;
    let too_large = || {
        format!(
            "the scene has {} triangle instances, more than brute force accepts ({MAX_BRUTE_FORCE_ITEMS})",
            scene.item_count()
        )
    };
    let (reference, reference_note) = match &config.reference {
        Reference::Auto if brute_force_ok => {
            let note = if config.algorithms.iter().any(|s| s.label() == "zbuffer") {
                "zbuffer: brute force, the ground truth"
            } else {
                "zbuffer: brute force, the ground truth (not requested; rendered as the reference)"
            };
            (Some(AlgoSpec::from(Algorithm::ZBUFFER)), note.to_string())
        }
        Reference::Auto => (
            Some(AlgoSpec::from(Algorithm::FRUSTUM)),
            format!(
                "frustum: {}; frustum culling removes only what lies outside the view, so its frames equal zbuffer's",
                too_large()
            ),
        ),
        Reference::Spec(spec) => {
            let bad = |reason: String| CompareError::BadReference {
                reference: spec.label(),
                reason,
            };
            if !spec.algorithm.info().conservative {
                return Err(bad("it is approximate; a reference must be conservative".into()));
            }
            if spec.algorithm == Algorithm::ZBUFFER && !brute_force_ok {
                return Err(bad(too_large()));
            }
            (Some(spec.clone()), format!("{}: chosen by the caller", spec.label()))
        }
        Reference::None => (None, "none: frames are not checked and there is no oracle".to_string()),
    };
    let reference_label = reference.as_ref().map(AlgoSpec::label);
    let mut skipped = Vec::new();
    let mut lineup: Vec<(AlgoSpec, bool)> = Vec::new();
    if let Some(r) = &reference {
        if !config.algorithms.iter().any(|s| s.label() == r.label()) {
            lineup.push((r.clone(), false));
        }
    }
    let mut seen = HashSet::new();
    for a in &config.algorithms {
        if !seen.insert(a.label()) {
            continue;
        }
        if a.algorithm == Algorithm::ZBUFFER && !brute_force_ok {
            skipped.push(Skipped {
                name: a.label(),
                reason: too_large(),
            });
            continue;
        }
        lineup.push((a.clone(), true));
    }
    if lineup.is_empty() {
        return Err(CompareError::NoAlgorithms);
    }

    // Build (preprocessing, timed).
    let mut contestants = Vec::with_capacity(lineup.len());
    let count = lineup.len();
    for (index, (spec, requested)) in lineup.into_iter().enumerate() {
        let label = spec.label();
        progress(CompareProgress::Building {
            label: &label,
            index,
            count,
        });
        let rss = PeakWindow::start();
        let t = Instant::now();
        let renderer = spec
            .build(Arc::clone(&scene), &config.options)
            .map_err(|source| CompareError::Build {
                algorithm: label.clone(),
                source,
            })?;
        let prepare_ms = ms(t.elapsed());
        let peak_rss_bytes = rss.end();
        if reference_label.as_deref() == Some(label.as_str()) && !renderer.is_conservative() {
            return Err(CompareError::BadReference {
                reference: label,
                reason: "this configuration is approximate; a reference must be conservative".into(),
            });
        }
        progress(CompareProgress::Built {
            label: &label,
            prepare_ms,
        });
        contestants.push(Contestant {
            spec,
            label,
            requested,
            memory_bytes_after_build: renderer.memory_bytes(),
            peak_rss_bytes,
            renderer,
            frame: Frame::new(config.width, config.height)?,
            prepare_ms,
            records: Vec::with_capacity(views.len()),
            stats: Vec::with_capacity(views.len()),
        });
    }
    // The frames every view is measured on: the reference's, or the first renderer's.
    let reference_index = reference_label.as_ref().map(|l| {
        contestants
            .iter()
            .position(|c| &c.label == l)
            .expect("the reference is always in the line-up")
    });
    let measured_index = reference_index.unwrap_or(0);

    // Render, interleaved.
    let mut oracle = Oracle::new(&config.options)?;
    let mut oracle_frame = Frame::new(config.width, config.height)?;
    let mut shaded_reference = Frame::new(config.width, config.height)?;
    let mut oracle_times = Vec::with_capacity(views.len());
    let mut oracle_identical = 0;
    let mut image = ImageMeasures {
        measured_on: contestants[measured_index].label.clone(),
        covered_pixels: Vec::with_capacity(views.len()),
        triangles_visible: Vec::with_capacity(views.len()),
        projected_pixels: config.image_complexity.then(|| Vec::with_capacity(views.len())),
    };
    let n = contestants.len();
    for (view_index, view) in views.iter().enumerate() {
        for k in 0..n {
            // Rotate the order so that no renderer always runs first (or right after another).
            let c = &mut contestants[(k + view_index) % n];
            let rss = PeakWindow::start();
            let t = Instant::now();
            let stats = c
                .renderer
                .render(view, &mut c.frame)
                .map_err(|source| CompareError::Render {
                    algorithm: c.label.clone(),
                    view_index,
                    source,
                })?;
            let time_ms = ms(t.elapsed());
            c.peak_rss_bytes = c.peak_rss_bytes.zip(rss.end()).map(|(a, b)| a.max(b));
            c.records.push(FrameRecord {
                time_ms,
                triangles_submitted: stats.triangles_submitted,
                triangles_rasterized: stats.triangles_rasterized,
                counters: stats.counters.clone(),
                ..FrameRecord::default()
            });
            c.stats.push(stats);
        }

        let measured_frame = &contestants[measured_index].frame;
        let visible = measured_frame.visible_items();
        image.covered_pixels.push(measured_frame.covered_pixel_count());
        image.triangles_visible.push(visible.len() as u64);
        if let Some(p) = &mut image.projected_pixels {
            p.push(image_complexity(&scene, view));
        }
        let Some(reference_index) = reference_index else {
            progress(CompareProgress::Frame {
                index: view_index,
                count: views.len(),
            });
            continue;
        };

        // Compare with the reference.
        let (before, rest) = contestants.split_at_mut(reference_index);
        let (reference_c, after) = rest.split_first_mut().expect("reference_index is in range");
        let reference_frame = &reference_c.frame;
        let mut reference_shaded = false;
        for c in before.iter_mut().chain(after.iter_mut()) {
            let record = c.records.last_mut().expect("a record was just pushed");
            if c.frame.same_visibility(reference_frame) {
                record.identical = true;
                continue;
            }
            record.item_error = Some(item_error(&c.frame, reference_frame));
            if !reference_shaded {
                shaded_reference.clone_from(reference_frame);
                shade(&mut shaded_reference, &scene, view);
                reference_shaded = true;
            }
            shade(&mut c.frame, &scene, view);
            let psnr = c.frame.color_psnr(&shaded_reference);
            record.psnr_db = psnr.is_finite().then_some(psnr);
        }
        reference_c
            .records
            .last_mut()
            .expect("a record was just pushed")
            .identical = true;

        // The oracle, from the reference's item buffer.
        let time_ms = oracle.render(&scene, view, &visible, &mut oracle_frame);
        oracle_times.push(time_ms);
        if oracle_frame.same_visibility(reference_frame) {
            oracle_identical += 1;
        }
        progress(CompareProgress::Frame {
            index: view_index,
            count: views.len(),
        });
    }

    // Summarise.
    let oracle_report = reference_index.map(|_| {
        let time = TimeSummary::of(&oracle_times);
        OracleReport {
            mean_ms: time.mean_ms,
            p95_ms: time.p95_ms,
            time,
            frames_identical: oracle_identical,
            per_frame_ms: oracle_times,
            triangles_visible: image.triangles_visible.clone(),
        }
    });
    let oracle_mean = oracle_report.as_ref().map_or(0.0, |o| o.mean_ms);
    let zbuffer_mean = contestants
        .iter()
        .find(|c| c.spec.algorithm == Algorithm::ZBUFFER)
        .map(|c| TimeSummary::of(&c.records.iter().map(|r| r.time_ms).collect::<Vec<_>>()).mean_ms);
    let visible_total: u64 = image.triangles_visible.iter().sum();
    let frames = views.len();
    let renderers = contestants
        .into_iter()
        .enumerate()
        .map(|(i, c)| {
            let times: Vec<f64> = c.records.iter().map(|r| r.time_ms).collect();
            let time = TimeSummary::of(&times);
            let ratio = |num: f64, den: f64| (den > 0.0 && num.is_finite()).then(|| num / den);
            let errors: Vec<f64> = c.records.iter().map(|r| r.item_error.unwrap_or(0.0)).collect();
            RendererReport {
                name: c.label,
                is_reference: Some(i) == reference_index,
                requested: c.requested,
                conservative: c.renderer.is_conservative(),
                frames,
                frames_identical: reference_index.map(|_| c.records.iter().filter(|r| r.identical).count()),
                mean_ms: time.mean_ms,
                p95_ms: time.p95_ms,
                speedup_vs_zbuffer: zbuffer_mean.and_then(|z| ratio(z, time.mean_ms)),
                vs_oracle: ratio(time.mean_ms, oracle_mean),
                triangles_rasterized: mean(c.records.iter().map(|r| r.triangles_rasterized as f64), frames),
                triangles_rasterized_total: c.records.iter().map(|r| r.triangles_rasterized).sum(),
                triangles_visible: visible_total as f64 / frames as f64,
                triangles_visible_total: visible_total,
                prepare_ms: c.prepare_ms,
                memory_bytes: c.renderer.memory_bytes(),
                memory_bytes_after_build: c.memory_bytes_after_build,
                peak_rss_bytes: c.peak_rss_bytes,
                mean_item_error: mean(errors.iter().copied(), frames),
                max_item_error: errors.iter().copied().fold(0.0, f64::max),
                min_psnr_db: c.records.iter().filter_map(|r| r.psnr_db).reduce(f64::min),
                phases: phase_means(&c.stats),
                stats: mean_stats(&c.stats),
                time,
                per_frame: c.records,
            }
        })
        .collect();
    Ok(CompareReport {
        width: config.width,
        height: config.height,
        frames,
        scene_triangles: scene.item_count(),
        scene_memory_bytes: scene.memory_bytes(),
        threads: match config.options.raster.threads {
            0 => rayon::current_num_threads(),
            n => n,
        },
        reference: reference_label,
        reference_note,
        oracle: oracle_report,
        image,
        renderers,
        skipped,
        process_peak_rss_bytes: process_peak_rss_bytes(),
    })
}

/// Rasterizes exactly a given set of items: the lower bound of any culling renderer.
struct Oracle {
    raster: Rasterizer,
}

/// The visible triangles of one mesh instance.
struct InstanceTriangles {
    mesh_node: NodeId,
    instance_base: ItemId,
    clip_from_object: occult_core::Mat4,
    triangle_indices: Vec<u32>,
}

impl Oracle {
    fn new(options: &RenderOptions) -> Result<Self> {
        Ok(Self {
            raster: Rasterizer::new(options.raster.clone())?,
        })
    }

    /// Clears `frame` and rasterizes the items `visible` (sorted, as
    /// [`Frame::visible_items`] returns them); returns the time of the clear and the draw, ms.
    /// Resolving items into draws is the oracle's knowledge and is not timed.
    fn render(&mut self, scene: &Scene, view: &View, visible: &[ItemId], frame: &mut Frame) -> f64 {
        // Items of one mesh instance are consecutive ids, so sorted items group by instance.
        let mut groups: Vec<InstanceTriangles> = Vec::new();
        for &item in visible {
            let Some(loc) = scene.resolve_item(item) else {
                continue; // Not an item of this scene (cannot happen for frames of this scene).
            };
            match groups.last_mut() {
                Some(g) if g.instance_base == loc.instance_base && g.mesh_node == loc.mesh_node => {
                    g.triangle_indices.push(loc.triangle_index)
                }
                _ => groups.push(InstanceTriangles {
                    mesh_node: loc.mesh_node,
                    instance_base: loc.instance_base,
                    clip_from_object: view.clip_from_object(&loc.world_from_object),
                    triangle_indices: vec![loc.triangle_index],
                }),
            }
        }
        let draws: Vec<Draw<'_>> = groups
            .iter()
            .filter_map(|g| {
                Some(Draw {
                    mesh: scene.node(g.mesh_node).mesh()?,
                    triangles: DrawTriangles::List(&g.triangle_indices),
                    clip_from_object: g.clip_from_object,
                    first_item: g.instance_base,
                })
            })
            .collect();
        let t = Instant::now();
        frame.clear();
        self.raster.draw(view, frame, &draws, RasterMode::Full);
        ms(t.elapsed())
    }
}

/// Image complexity |Ω| of one view (Han & Zeiger §I): the summed screen area, in pixels, of
/// every triangle instance clipped to the view frustum (near, far, four sides), back faces
/// included. Instances whose bounds lie outside the frustum are skipped whole; the cost is one
/// transform and clip per triangle instance in the view, over rayon's threads.
pub fn image_complexity(scene: &Scene, view: &View) -> f64 {
    let mut instances: Vec<(Mat4, &Mesh)> = Vec::new();
    collect_in_frustum(scene, view, scene.root(), &Affine3A::IDENTITY, &mut instances);
    let (w, h) = (view.width() as f64, view.height() as f64);
    let (near, far) = (view.camera().near, view.camera().far);
    instances
        .par_iter()
        .map(|(clip_from_object, mesh)| {
            let p = mesh.positions();
            mesh.triangles()
                .par_chunks(4096)
                .map(|chunk| {
                    chunk
                        .iter()
                        .map(|t| {
                            let c = t.map(|i| *clip_from_object * p[i as usize].extend(1.0));
                            clipped_screen_area(&c, near, far) * 0.25 * w * h
                        })
                        .sum::<f64>()
                })
                .sum::<f64>()
        })
        .sum()
}

/// The mesh instances below `id` whose bounds are not outside the view frustum.
fn collect_in_frustum<'s>(
    scene: &'s Scene,
    view: &View,
    id: NodeId,
    world_from_node: &Affine3A,
    out: &mut Vec<(Mat4, &'s Mesh)>,
) {
    let node = scene.node(id);
    if view.frustum(world_from_node).classify_aabb(&node.bounds()) == Containment::Outside {
        return;
    }
    match node.kind() {
        NodeKind::Mesh(m) => out.push((view.clip_from_object(world_from_node), m)),
        NodeKind::Group(instances) => {
            for inst in instances {
                let world_from_child = compose(world_from_node, &inst.parent_from_child);
                collect_in_frustum(scene, view, inst.child, &world_from_child, out);
            }
        }
    }
}

/// Area in normalized device coordinates (the screen is 2 × 2) of the clip-space triangle `c`
/// clipped to `near <= w <= far` and `|x|, |y| <= w` (Sutherland–Hodgman in homogeneous
/// coordinates).
fn clipped_screen_area(c: &[Vec4; 3], near: f32, far: f32) -> f64 {
    let planes: [fn(&Vec4, f32, f32) -> f32; 6] = [
        |v, n, _| v.w - n,
        |v, _, f| f - v.w,
        |v, _, _| v.w + v.x,
        |v, _, _| v.w - v.x,
        |v, _, _| v.w + v.y,
        |v, _, _| v.w - v.y,
    ];
    // Up to 3 + 6 vertices after six planes.
    let mut poly = [Vec4::ZERO; 9];
    poly[..3].copy_from_slice(c);
    let mut len = 3;
    let mut next = [Vec4::ZERO; 9];
    for plane in planes {
        let d: [f32; 9] = std::array::from_fn(|i| if i < len { plane(&poly[i], near, far) } else { 0.0 });
        if d[..len].iter().all(|&x| x >= 0.0) {
            continue;
        }
        let mut n = 0;
        for i in 0..len {
            let j = (i + 1) % len;
            if d[i] >= 0.0 {
                next[n] = poly[i];
                n += 1;
            }
            if (d[i] >= 0.0) != (d[j] >= 0.0) {
                next[n] = poly[i] + (poly[j] - poly[i]) * (d[i] / (d[i] - d[j]));
                n += 1;
            }
        }
        std::mem::swap(&mut poly, &mut next);
        len = n;
        if len < 3 {
            return 0.0;
        }
    }
    let ndc = |v: &Vec4| ((v.x / v.w) as f64, (v.y / v.w) as f64);
    let twice: f64 = (0..len)
        .map(|i| {
            let (a, b) = (ndc(&poly[i]), ndc(&poly[(i + 1) % len]));
            a.0 * b.1 - b.0 * a.1
        })
        .sum();
    twice.abs() * 0.5
}

/// Share of pixels covered in either frame whose item differs (0 when neither covers any).
fn item_error(frame: &Frame, reference: &Frame) -> f64 {
    let covered = frame
        .items()
        .iter()
        .zip(reference.items())
        .filter(|(&a, &b)| a != NO_ITEM || b != NO_ITEM)
        .count();
    if covered == 0 {
        return 0.0;
    }
    frame.differing_item_count(reference) as f64 / covered as f64
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn mean(values: impl Iterator<Item = f64>, count: usize) -> f64 {
    if count == 0 {
        0.0
    } else {
        values.sum::<f64>() / count as f64
    }
}

fn phase_means(stats: &[FrameStats]) -> Vec<PhaseMean> {
    let mut phases: Vec<Phase> = Vec::new();
    for s in stats {
        for &(p, _) in &s.phases.0 {
            if !phases.contains(&p) {
                phases.push(p);
            }
        }
    }
    phases
        .into_iter()
        .map(|phase| PhaseMean {
            phase,
            mean_ms: mean(stats.iter().map(|s| ms(s.phases.get(phase))), stats.len()),
        })
        .collect()
}

fn mean_stats(stats: &[FrameStats]) -> MeanStats {
    let n = stats.len();
    let m = |f: fn(&FrameStats) -> u64| mean(stats.iter().map(|s| f(s) as f64), n);
    MeanStats {
        triangles_submitted: m(|s| s.triangles_submitted),
        triangles_rasterized: m(|s| s.triangles_rasterized),
        fragments_written: m(|s| s.fragments_written),
        nodes_visited: m(|s| s.nodes_visited),
        boxes_tested: m(|s| s.boxes_tested),
        boxes_culled: m(|s| s.boxes_culled),
        rects_tested: m(|s| s.rects_tested),
        rects_culled: m(|s| s.rects_culled),
        rays_cast: m(|s| s.rays_cast),
        samples_drawn: m(|s| s.samples_drawn),
        counters: {
            let mut sums = std::collections::BTreeMap::new();
            for s in stats {
                for &(k, v) in &s.counters.0 {
                    *sums.entry(k).or_insert(0.0) += v as f64;
                }
            }
            sums.values_mut().for_each(|v| *v /= n.max(1) as f64);
            sums
        },
        total_ms: mean(stats.iter().map(|s| ms(s.total)), n),
    }
}

/// The highest `VmHWM` read so far, KiB: the kernel's mark is reset for per-renderer peaks
/// ([`PeakWindow`]), so the process's own peak is the highest of every reading.
static PROCESS_PEAK_KIB: AtomicU64 = AtomicU64::new(0);

/// Peak resident set size of this process since it started, bytes: the kernel's high-water
/// mark (`VmHWM` of `/proc/self/status`), or the highest one read before one of the resets of
/// [`PeakWindow`] if that was higher. `None` where `/proc/self/status` is unavailable
/// (not Linux).
pub fn process_peak_rss_bytes() -> Option<u64> {
    high_water_mark_kib().map(|kib| PROCESS_PEAK_KIB.load(Ordering::Relaxed).max(kib) * 1024)
}

/// The kernel's resident high-water mark (`VmHWM`) now, KiB, folded into
/// [`PROCESS_PEAK_KIB`]; `None` where `/proc/self/status` is unavailable.
fn high_water_mark_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line
        .trim_start_matches("VmHWM:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    PROCESS_PEAK_KIB.fetch_max(kib, Ordering::Relaxed);
    Some(kib)
}

/// The process's resident peak over a stretch of work: [`PeakWindow::start`] resets the
/// kernel's high-water mark to the current resident size, [`PeakWindow::end`] reads it.
struct PeakWindow {
    /// Whether the reset succeeded.
    reset: bool,
}

impl PeakWindow {
    /// Resets the mark (after folding the current one into the process peak): `5` written to
    /// `/proc/self/clear_refs` (Linux; see proc(5)).
    fn start() -> Self {
        let reset = high_water_mark_kib().is_some() && std::fs::write("/proc/self/clear_refs", "5").is_ok();
        Self { reset }
    }

    /// The peak since [`PeakWindow::start`], bytes; `None` when the mark was not reset (it
    /// would be an older peak) or cannot be read.
    fn end(self) -> Option<u64> {
        self.reset.then(high_water_mark_kib).flatten().map(|kib| kib * 1024)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use occult_core::{Instance, SceneBuilder, Vec3};

    /// A 6×6 grid of unit cubes (instanced) on a ground quad: cubes hide each other and the
    /// ground from most views.
    fn cubes() -> Arc<Scene> {
        let at = (0..36).map(|k| Vec3::new((k / 6) as f32 * 2.0 - 5.0, 0.0, (k % 6) as f32 * 2.0 - 5.0));
        crate::tests::cubes_on_ground([-8.0, 8.0, -8.0, 8.0], at)
    }

    fn circle(n: usize) -> Vec<Camera> {
        (0..n)
            .map(|i| {
                let a = i as f32 / n as f32 * std::f32::consts::TAU;
                Camera::look_at(Vec3::new(9.0 * a.cos(), 2.0, 9.0 * a.sin()), Vec3::new(0.0, 0.0, 0.0))
            })
            .collect()
    }

    fn run(algorithms: Vec<Algorithm>, cameras: &[Camera]) -> Result<CompareReport> {
        let mut config = CompareConfig::new(algorithms, 96, 64);
        config.options.raster.threads = 2;
        compare(cubes(), cameras, &config, &mut |_| {})
    }

    #[test]
    fn frustum_is_identical_to_zbuffer_on_every_frame() {
        let cameras = circle(6);
        let report = run(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], &cameras).unwrap();
        assert_eq!(report.reference.as_deref(), Some("zbuffer"));
        assert_eq!(report.frames, 6);
        for r in &report.renderers {
            assert_eq!(r.frames, 6);
            assert_eq!(r.frames_identical, Some(6), "{} differs from the reference", r.name);
            assert!(r
                .per_frame
                .iter()
                .all(|f| f.identical && f.item_error.is_none() && f.psnr_db.is_none()));
            assert_eq!(r.mean_item_error, 0.0);
            assert!(r.min_psnr_db.is_none());
        }
        assert_eq!(
            report.oracle.as_ref().unwrap().frames_identical,
            6,
            "rasterizing the visible set must reproduce the frame"
        );
    }

    #[test]
    fn report_numbers_are_consistent() {
        let cameras = circle(5);
        let report = run(
            vec![Algorithm::FRUSTUM, Algorithm::ZBUFFER, Algorithm::FRUSTUM],
            &cameras,
        )
        .unwrap();
        let names: Vec<_> = report.renderers.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["frustum", "zbuffer"], "requested order, duplicates dropped");
        assert_eq!(report.scene_triangles, 2 + 36 * 12);
        let z = report.renderer("zbuffer").unwrap();
        let f = report.renderer("frustum").unwrap();
        assert!(z.is_reference && !f.is_reference && z.requested && f.requested);
        assert_eq!(z.speedup_vs_zbuffer, Some(1.0));
        assert!((f.speedup_vs_zbuffer.unwrap() - z.mean_ms / f.mean_ms).abs() < 1e-9);
        // zbuffer submits everything; frustum never more.
        assert_eq!(z.stats.triangles_submitted, report.scene_triangles as f64);
        for r in [z, f] {
            assert_eq!(r.per_frame.len(), 5);
            let total: u64 = r.per_frame.iter().map(|p| p.triangles_rasterized).sum();
            assert_eq!(r.triangles_rasterized_total, total);
            assert!((r.triangles_rasterized - total as f64 / 5.0).abs() < 1e-9);
            assert_eq!(r.stats.triangles_rasterized, r.triangles_rasterized);
            let mean_ms = r.per_frame.iter().map(|p| p.time_ms).sum::<f64>() / 5.0;
            assert!((r.mean_ms - mean_ms).abs() < 1e-9);
            assert!(r.time.min_ms <= r.time.median_ms && r.time.median_ms <= r.p95_ms && r.p95_ms <= r.time.max_ms);
            assert!(r.vs_oracle.unwrap() > 0.0);
            assert!(r.prepare_ms >= 0.0);
            assert!(!r.phases.is_empty());
        }
        assert!(f.stats.triangles_submitted <= z.stats.triangles_submitted);
        // Visible triangles: from the item buffer, never more than rasterized.
        assert_eq!(report.oracle.as_ref().unwrap().triangles_visible.len(), 5);
        let visible: u64 = report.oracle.as_ref().unwrap().triangles_visible.iter().sum();
        assert_eq!(z.triangles_visible_total, visible);
        assert!(visible > 0);
        for (i, &v) in report.oracle.as_ref().unwrap().triangles_visible.iter().enumerate() {
            assert!(v <= z.per_frame[i].triangles_rasterized && v < report.scene_triangles);
        }
        assert!(report.process_peak_rss_bytes.is_none_or(|b| b > 0));
    }

    #[test]
    fn peak_memory_is_measured_per_renderer_where_the_kernel_allows() {
        let report = run(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], &circle(2)).unwrap();
        let process = report.process_peak_rss_bytes;
        let measurable = cfg!(target_os = "linux") && std::fs::write("/proc/self/clear_refs", "5").is_ok();
        for r in &report.renderers {
            match r.peak_rss_bytes {
                Some(peak) => {
                    assert!(measurable, "{}: a peak where none can be measured", r.name);
                    assert!(peak > 0);
                    // Each reading is of the whole process, so never above its peak.
                    assert!(peak <= process.unwrap(), "{}: {peak} > {process:?}", r.name);
                }
                None => assert!(!measurable, "{}: no peak although the mark can be reset", r.name),
            }
        }
    }

    #[test]
    fn the_process_peak_survives_the_resets() {
        if process_peak_rss_bytes().is_none() {
            return;
        }
        // 64 MiB touched and freed, then the mark reset: the process peak still holds it.
        let block = vec![1u8; 64 << 20];
        assert_eq!(block.iter().step_by(4096).map(|&b| b as usize).sum::<usize>(), 16384);
        let grown = process_peak_rss_bytes().unwrap();
        drop(block);
        assert!(grown >= 64 << 20, "{grown}");
        let window = PeakWindow::start();
        let after = window.end();
        assert!(process_peak_rss_bytes().unwrap() >= grown);
        assert!(after.is_none_or(|a| a <= process_peak_rss_bytes().unwrap()));
    }

    #[test]
    fn reference_is_added_when_not_requested() {
        let report = run(vec![Algorithm::FRUSTUM], &circle(2)).unwrap();
        let z = &report.renderers[0];
        assert_eq!((z.name.as_str(), z.is_reference, z.requested), ("zbuffer", true, false));
        assert!(report.reference_note.contains("not requested"));
        assert_eq!(report.renderers[1].frames_identical, Some(2));
    }

    #[test]
    fn scenes_too_large_for_brute_force_use_frustum_as_reference() {
        // 10^10 triangle instances along +x, ten times farther apart at each level; the camera
        // sees only the first few.
        let mut b = SceneBuilder::new();
        let tri = Mesh::new(
            vec![Vec3::ZERO, Vec3::new(0.8, 0.0, 0.0), Vec3::new(0.0, 0.8, 0.0)],
            vec![[0, 1, 2]],
        )
        .unwrap();
        let mut id = b.add_mesh("tri", tri).unwrap();
        for level in 0..10 {
            let pitch = 10f32.powi(level);
            let row: Vec<_> = (0..10)
                .map(|i| Instance {
                    parent_from_child: Affine3A::from_translation(Vec3::X * pitch * i as f32),
                    child: id,
                })
                .collect();
            id = b.add_group(format!("level{level}"), row).unwrap();
        }
        let scene = Arc::new(b.build(id).unwrap());
        assert!(scene.item_count() > MAX_BRUTE_FORCE_ITEMS);
        let mut camera = Camera::look_at(Vec3::new(4.0, 0.5, 6.0), Vec3::new(4.0, 0.5, 0.0));
        camera.far = 30.0;
        let config = CompareConfig::new(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], 64, 48);
        let report = compare(scene, &[camera, camera], &config, &mut |_| {}).unwrap();
        assert_eq!(report.reference.as_deref(), Some("frustum"));
        assert!(
            report.reference_note.contains("more than brute force accepts"),
            "{}",
            report.reference_note
        );
        assert_eq!(report.skipped.len(), 1);
        assert_eq!(report.skipped[0].name, "zbuffer");
        assert_eq!(report.renderers.len(), 1);
        let f = &report.renderers[0];
        assert!(f.is_reference && f.requested && f.speedup_vs_zbuffer.is_none());
        assert_eq!(f.frames_identical, Some(2));
        assert!(report.oracle.as_ref().unwrap().triangles_visible[0] > 0);
        assert_eq!(report.oracle.as_ref().unwrap().frames_identical, 2);
    }

    #[test]
    fn empty_inputs_are_errors() {
        assert!(matches!(run(vec![Algorithm::FRUSTUM], &[]), Err(CompareError::NoViews)));
        assert!(matches!(run(vec![], &circle(1)), Err(CompareError::NoAlgorithms)));
    }

    #[test]
    fn degenerate_camera_and_bad_size_are_errors() {
        let mut cameras = circle(3);
        cameras[1].target = cameras[1].eye;
        assert!(matches!(
            run(vec![Algorithm::FRUSTUM], &cameras),
            Err(CompareError::BadView { view_index: 1, .. })
        ));
        let config = CompareConfig::new(vec![Algorithm::FRUSTUM], 0, 64);
        assert!(matches!(
            compare(cubes(), &circle(1), &config, &mut |_| {}),
            Err(CompareError::BadView { .. })
        ));
    }

    #[test]
    fn views_that_see_nothing_are_fine() {
        let away = Camera::look_at(Vec3::new(0.0, 50.0, 0.0), Vec3::new(0.0, 100.0, 1.0));
        let report = run(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], &[away]).unwrap();
        assert_eq!(report.oracle.as_ref().unwrap().triangles_visible, vec![0]);
        assert!(report.renderers.iter().all(|r| r.frames_identical == Some(1)));
    }

    #[test]
    fn differing_frames_are_measured() {
        let scene = cubes();
        let view = View::new(circle(1)[0], 32, 24).unwrap();
        let mut a = Frame::new(32, 24).unwrap();
        let mut r = Algorithm::ZBUFFER
            .build(Arc::clone(&scene), &RenderOptions::default())
            .unwrap();
        r.render(&view, &mut a).unwrap();
        let mut b = a.clone();
        assert_eq!(item_error(&a, &b), 0.0);
        b.clear();
        assert_eq!(item_error(&b, &a), 1.0, "all covered pixels lost");
        assert_eq!(item_error(&b, &b), 0.0);
    }

    #[test]
    fn reference_can_be_chosen_or_none() {
        let cameras = circle(4);
        let mut config = CompareConfig::new(vec![Algorithm::ZBUFFER, Algorithm::FRUSTUM], 96, 64);
        config.reference = Reference::Spec(AlgoSpec::from(Algorithm::FRUSTUM));
        let report = compare(cubes(), &cameras, &config, &mut |_| {}).unwrap();
        assert_eq!(report.reference.as_deref(), Some("frustum"));
        assert!(report.renderer("frustum").unwrap().is_reference);
        assert_eq!(report.renderer("zbuffer").unwrap().frames_identical, Some(4));
        assert!(report.oracle.is_some());

        config.algorithms = vec![AlgoSpec::from(Algorithm::FRUSTUM)];
        config.reference = Reference::None;
        let report = compare(cubes(), &cameras, &config, &mut |_| {}).unwrap();
        assert_eq!(report.reference, None);
        assert!(report.oracle.is_none());
        assert_eq!(report.renderers.len(), 1, "no reference is added");
        let f = report.renderer("frustum").unwrap();
        assert!(!f.is_reference);
        assert_eq!(f.frames_identical, None, "nothing is checked");
        assert_eq!(f.vs_oracle, None);
        assert_eq!(report.image.measured_on, "frustum");
        assert_eq!(report.image.covered_pixels.len(), 4);
        assert!(report.image.covered_pixels.iter().all(|&c| c > 0));
        assert!(
            f.triangles_visible > 0.0,
            "visible triangles come from the first renderer's frames"
        );
    }

    #[test]
    fn approximate_or_impossible_references_are_refused() {
        let cameras = circle(1);
        let mut config = CompareConfig::new(vec![Algorithm::FRUSTUM], 32, 32);
        config.reference = Reference::Spec(AlgoSpec::parse("rzb").unwrap());
        let e = compare(cubes(), &cameras, &config, &mut |_| {}).unwrap_err();
        assert!(matches!(e, CompareError::BadReference { .. }), "{e}");
        assert!(e.to_string().contains("conservative"), "{e}");
        config.reference = Reference::Spec(AlgoSpec::parse("lzb:mode=naive").unwrap());
        let e = compare(cubes(), &cameras, &config, &mut |_| {}).unwrap_err();
        assert!(e.to_string().contains("approximate"), "{e}");
    }

    #[test]
    fn image_complexity_is_the_clipped_screen_area_of_every_layer() {
        // Two full-screen squares, one behind the other, facing the camera: every pixel is
        // covered twice, so image complexity is 2 w h and depth complexity 2.
        let quad = |z: f32| {
            Mesh::new(
                vec![
                    Vec3::new(-100.0, -100.0, z),
                    Vec3::new(100.0, -100.0, z),
                    Vec3::new(100.0, 100.0, z),
                    Vec3::new(-100.0, 100.0, z),
                ],
                vec![[0, 1, 2], [0, 2, 3]],
            )
            .unwrap()
        };
        let mut b = SceneBuilder::new();
        let near = b.add_mesh("near", quad(0.0)).unwrap();
        let far = b.add_mesh("far", quad(-5.0)).unwrap();
        let root = b
            .add_group(
                "layers",
                [near, far]
                    .map(|child| Instance {
                        parent_from_child: Affine3A::IDENTITY,
                        child,
                    })
                    .to_vec(),
            )
            .unwrap();
        let scene = Arc::new(b.build(root).unwrap());
        let camera = Camera::look_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO);
        let view = View::new(camera, 64, 48).unwrap();
        let area = image_complexity(&scene, &view);
        assert!((area - 2.0 * 64.0 * 48.0).abs() < 1e-3 * area, "{area}");

        // A triangle wholly inside the view: its projected area.
        let tri = Mesh::new(
            vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2]],
        )
        .unwrap();
        let scene = Arc::new(Scene::from_mesh("tri", tri).unwrap());
        let view = View::new(camera, 100, 100).unwrap();
        let c = view.clip_from_world();
        let px = |p: Vec3| {
            let v = c * p.extend(1.0);
            (v.x as f64 / v.w as f64 * 50.0, v.y as f64 / v.w as f64 * 50.0)
        };
        let (a, b2, d) = (px(Vec3::ZERO), px(Vec3::X), px(Vec3::Y));
        let expected = ((b2.0 - a.0) * (d.1 - a.1) - (d.0 - a.0) * (b2.1 - a.1)).abs() / 2.0;
        let area = image_complexity(&scene, &view);
        assert!((area - expected).abs() < 1e-3 * expected, "{area} vs {expected}");

        let mut config = CompareConfig::new(vec![Algorithm::ZBUFFER], 64, 48);
        config.image_complexity = true;
        let report = compare(cubes(), &circle(2), &config, &mut |_| {}).unwrap();
        let dc = report.image.mean_depth_complexity().unwrap();
        assert!(dc >= 1.0, "depth complexity {dc}");
    }

    #[test]
    fn time_summary_uses_nearest_rank() {
        let t: Vec<f64> = (1..=20).map(f64::from).collect();
        let s = TimeSummary::of(&t);
        assert_eq!(
            (s.mean_ms, s.median_ms, s.p95_ms, s.min_ms, s.max_ms),
            (10.5, 10.0, 19.0, 1.0, 20.0)
        );
        assert_eq!(TimeSummary::of(&[3.0]).p95_ms, 3.0);
        assert_eq!(TimeSummary::of(&[]), TimeSummary::default());
    }
}
