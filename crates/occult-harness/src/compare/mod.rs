//! The comparison harness: several renderers, one scene, one camera path, one process.
//!
//! [`compare`] builds each requested renderer (timing its preprocessing), then renders every
//! view with every renderer **interleaved frame by frame** (view 0 with all renderers, then
//! view 1, ...; the order of the renderers rotates from frame to frame), so that machine noise,
//! thermal state and cache warmth hit all of them alike. Each frame of each renderer is compared
//! with the reference renderer's frame of the same view:
//!
//! - **reference** ([`Reference`]): by default `zbuffer` whenever the scene has at most
//!   [`MAX_BRUTE_FORCE_ITEMS`] triangle instances, otherwise `frustum` (the conservative
//!   renderer that scales); or any conservative renderer
//!   named by the caller; or none, for scenes even `frustum` cannot render in useful time
//!   (10^14 triangles): then no frame is checked and there is no oracle. The reference is always
//!   rendered and reported, requested or not ([`RendererReport::requested`] says which), so a
//!   report always holds the renderer its numbers are relative to. The frames checked against
//!   are drawn by a second instance of the reference, untimed; the timed instance is a
//!   contestant like any other, its frames checked too. Timed in the role itself, a reference
//!   ran 3–10 % faster than an identical copy of it (`zbuffer` against `zbuffer:bands=1`),
//!   which flattered every ratio to it. The second instance and its frame stay in memory
//!   while every renderer is measured (the process's peak resident memory holds them).
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
//!   after its last frame; and, **only when asked** ([`CompareConfig::peak_rss`]), the peak
//!   resident set size of the process while it was built and while it rendered
//!   ([`RendererReport::peak_rss_bytes`]): on Linux the kernel's high-water mark is reset (`5`
//!   written to `/proc/self/clear_refs`) before the build and before each of its frames, and
//!   read (`VmHWM` of `/proc/self/status`) after each ([`crate::memory`]). It is the whole
//!   process's memory: the scene, the harness's frames, and, because renderers are built one
//!   after another and then render interleaved, every renderer built before it (during its
//!   build) or all of them (during its frames). What tells renderers apart is what their build
//!   and frames add.
//!
//! Times are wall-clock times of whole [`Renderer::render`] calls (clearing included), in
//! milliseconds; the memory readings lie outside the timed calls. Nothing here reads or writes
//! files, prints or touches process-wide state, except the `/proc/self` files above when
//! [`CompareConfig::peak_rss`] asks for them (Linux); the CLI writes the report out.
//!
//! The work is done in named steps: `Lineup::choose` (reference and line-up), `build`
//! (preprocessing, timed), per view `render_view` (every renderer, interleaved),
//! `check_view` (against the reference) and the oracle, then `report` (the summaries).
//!
//! Cost: every renderer's frames, the reference's once more (untimed), plus one shading pass
//! per non-identical frame; one frame buffer (16 bytes a pixel) per renderer plus three, and
//! the reference renderer's structures twice.
//!
//! ```
//! use std::sync::Arc;
//! use occult_core::{Camera, Mesh, Scene, Vec3};
//! use occult_harness::compare::{compare, CompareConfig};
//! use occult_render::Algorithm;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])?;
//! let scene = Arc::new(Scene::from_mesh("tri", mesh)?);
//! let cameras = [Camera::look_at(Vec3::new(0.3, 0.3, 2.0), Vec3::new(0.3, 0.3, 0.0))];
//! let config = CompareConfig::new(vec![Algorithm::FRUSTUM], 32, 32);
//! let report = compare(scene, &cameras, &config, &mut |_| {})?;
//! assert_eq!(report.reference.as_deref(), Some("zbuffer")); // rendered although not requested
//! let frustum = report.renderer("frustum").expect("frustum is in the report");
//! assert_eq!(frustum.frames_identical, Some(1));
//! let oracle = report.oracle.as_ref().expect("a brute-force reference comes with an oracle");
//! assert_eq!(oracle.triangles_visible, [1]);
//! # Ok(())
//! # }
//! ```
//!
//! Deviation from the harness first sketched (`views: &[View]`): it takes cameras and one
//! resolution ([`CompareConfig::width`], [`CompareConfig::height`]), since every frame of a
//! comparison must have the same size and camera paths yield cameras.

mod oracle;
mod report;
#[cfg(test)]
mod tests;

use std::collections::HashSet;
use std::sync::Arc;
use std::time::Instant;

use occult_core::{Camera, CoreError, ItemId, Scene, View};
use occult_raster::{shade, Frame, RasterError};
use occult_render::zbuffer::MAX_BRUTE_FORCE_ITEMS;
use occult_render::{AlgoSpec, Algorithm, FrameStats, RenderError, RenderOptions, Renderer};
use thiserror::Error;

use crate::memory::PeakRss;
pub use oracle::image_complexity;
use oracle::{item_error, Oracle};
use report::{mean, mean_stats, ms, phase_means};
pub use report::{
    CompareReport, FrameRecord, ImageMeasures, MeanStats, OracleReport, PhaseMean, RendererReport, Skipped, TimeSummary,
};
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
    /// Measure the peak resident set size of the **whole process** per renderer and for the
    /// process ([`RendererReport::peak_rss_bytes`], [`CompareReport::process_peak_rss_bytes`]):
    /// resets the kernel's high-water mark of this process before every build and frame (see
    /// [`crate::memory`]). `None` (the default): no process state is read or written and those
    /// fields are `None`. Pass clones of one [`PeakRss`] to every comparison of a process so
    /// that the process peak survives the resets.
    pub peak_rss: Option<PeakRss>,
    /// For every frame that differs from the reference, an image of where
    /// ([`CompareProgress::Differs`]): pixels wrong by the paper's criterion red, another item
    /// visible through the pixel yellow, the rest the reference dimmed.
    pub diff_images: bool,
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
            peak_rss: None,
            diff_images: false,
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
    /// A renderer's frame of view `index` differs from the reference's (only with
    /// [`CompareConfig::diff_images`]): where, as an image ([`CompareConfig::diff_images`]).
    Differs {
        /// The renderer's label.
        label: &'a str,
        /// The view, from 0.
        index: usize,
        /// The image.
        image: &'a image::RgbaImage,
    },
    /// View `index` of `count` was rendered by every renderer and compared.
    Frame {
        /// The view, from 0.
        index: usize,
        /// Views in all.
        count: usize,
    },
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
    let lineup = Lineup::choose(&scene, config)?;
    let mut contestants = build(&scene, config, &lineup, progress)?;
    let reference_index = lineup.reference_label.as_ref().map(|l| {
        contestants
            .iter()
            .position(|c| &c.label == l)
            .expect("the reference is always in the line-up")
    });
    // The frames every view is checked against: the reference's, drawn by an instance of its
    // own, untimed ([`Checker`]).
    let mut checker = match reference_index {
        Some(i) => Some(Checker::build(&scene, config, &lineup, &contestants[i], progress)?),
        None => None,
    };
    let mut checks = Checks::new(config, &contestants[reference_index.unwrap_or(0)].label, views.len())?;
    for (view_index, view) in views.iter().enumerate() {
        render_view(&mut contestants, view, view_index, config.peak_rss.as_ref())?;
        if let Some(checker) = &mut checker {
            checker.render(view, view_index)?;
            checks.measure_image(&scene, view, &checker.frame);
            checks.check_view(&scene, view, view_index, &mut contestants, &checker.frame)?;
            for (label, image) in checks.diffs.drain(..) {
                progress(CompareProgress::Differs {
                    label: &label,
                    index: view_index,
                    image: &image,
                });
            }
        } else {
            // Nothing checked: the image is measured on the first renderer's frames.
            checks.measure_image(&scene, view, &contestants[0].frame);
        }
        progress(CompareProgress::Frame {
            index: view_index,
            count: views.len(),
        });
    }
    Ok(report(&scene, config, lineup, contestants, reference_index, checks))
}

/// The renderers that take part, and the reference among them.
struct Lineup {
    /// Each renderer, and whether it was requested (the reference may not have been).
    entries: Vec<(AlgoSpec, bool)>,
    /// The reference's label; `None` when frames are not checked.
    reference_label: Option<String>,
    /// Why that reference.
    reference_note: String,
    /// Requested renderers that cannot take part.
    skipped: Vec<Skipped>,
}

impl Lineup {
    /// Chooses the reference ([`CompareConfig::reference`]) and the line-up: the reference
    /// first when it was not requested, then the requested renderers in order, duplicates
    /// dropped, `zbuffer` skipped on scenes too large for brute force.
    fn choose(scene: &Scene, config: &CompareConfig) -> Result<Self> {
        let brute_force_ok = scene.item_count() <= MAX_BRUTE_FORCE_ITEMS;
        let (reference, reference_note) = choose_reference(scene, config)?;
        let reference_label = reference.as_ref().map(AlgoSpec::label);
        let mut skipped = Vec::new();
        let mut entries: Vec<(AlgoSpec, bool)> = Vec::new();
        if let Some(r) = &reference {
            if !config.algorithms.iter().any(|s| s.label() == r.label()) {
                entries.push((r.clone(), false));
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
                    reason: too_large(scene),
                });
                continue;
            }
            entries.push((a.clone(), true));
        }
        if entries.is_empty() {
            return Err(CompareError::NoAlgorithms);
        }
        Ok(Self {
            entries,
            reference_label,
            reference_note,
            skipped,
        })
    }
}

/// Why `zbuffer` cannot render `scene`.
fn too_large(scene: &Scene) -> String {
    format!(
        "the scene has {} triangle instances, more than brute force accepts ({MAX_BRUTE_FORCE_ITEMS})",
        scene.item_count()
    )
}

/// The reference of [`CompareConfig::reference`] on `scene` (module doc), and why.
fn choose_reference(scene: &Scene, config: &CompareConfig) -> Result<(Option<AlgoSpec>, String)> {
    let brute_force_ok = scene.item_count() <= MAX_BRUTE_FORCE_ITEMS;
    Ok(match &config.reference {
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
                too_large(scene)
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
                return Err(bad(too_large(scene)));
            }
            (Some(spec.clone()), format!("{}: chosen by the caller", spec.label()))
        }
        Reference::None => (None, "none: frames are not checked and there is no oracle".to_string()),
    })
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
    /// Highest process high-water mark over its build and frames; `None` when not asked for
    /// or once one could not be measured.
    peak_rss_bytes: Option<u64>,
    records: Vec<FrameRecord>,
    stats: Vec<FrameStats>,
}

/// The untimed instance of the reference renderer whose frames every view is checked
/// against, the oracle drawn from and the image measured on. The reference's timed instance is
/// a contestant like any other, checked against these frames too: the role itself made a
/// timed reference faster than an identical copy of it by 3–10 % (`zbuffer` against
/// `zbuffer:bands=1` on `sponza` `circle:96`, reference either one; not cache warmth:
/// overwriting 64 MiB before every timed frame left it), which flattered every ratio to it.
struct Checker {
    /// `<reference> (reference frames)`: its name in progress and errors.
    label: String,
    renderer: Box<dyn Renderer>,
    frame: Frame,
}

impl Checker {
    /// A second instance of `reference`'s renderer (its preprocessing untimed, reported to
    /// `progress` as a build of its own).
    fn build(
        scene: &Arc<Scene>,
        config: &CompareConfig,
        lineup: &Lineup,
        reference: &Contestant,
        progress: &mut dyn FnMut(CompareProgress),
    ) -> Result<Self> {
        let label = format!("{} (reference frames)", reference.label);
        // The last of the builds that `build` counted.
        let count = lineup_builds(lineup);
        progress(CompareProgress::Building {
            label: &label,
            index: count - 1,
            count,
        });
        let t = Instant::now();
        let renderer = build_prepared(&reference.spec, scene, config).map_err(|source| CompareError::Build {
            algorithm: label.clone(),
            source,
        })?;
        progress(CompareProgress::Built {
            label: &label,
            prepare_ms: ms(t.elapsed()),
        });
        Ok(Self {
            label,
            renderer,
            frame: Frame::new(config.width, config.height)?,
        })
    }

    /// Draws the reference frame of `view`.
    fn render(&mut self, view: &View, view_index: usize) -> Result<()> {
        self.renderer
            .render(view, &mut self.frame)
            .map_err(|source| CompareError::Render {
                algorithm: self.label.clone(),
                view_index,
                source,
            })?;
        Ok(())
    }
}

/// Runs `work` inside a peak-memory window of `rss` when there is one; returns what `work`
/// returned and the window's peak (`None` without `rss`).
fn within_peak_window<T>(rss: Option<&PeakRss>, work: impl FnOnce() -> T) -> (T, Option<u64>) {
    let window = rss.map(PeakRss::window);
    let out = work();
    (out, window.and_then(|w| w.end()))
}

/// `spec`'s renderer of `scene`, prepared for frames of the comparison's size
/// ([`Renderer::prepare`]): its preparation, not its first frame, pays for its frame-sized
/// buffers.
fn build_prepared(
    spec: &AlgoSpec,
    scene: &Arc<Scene>,
    config: &CompareConfig,
) -> occult_render::Result<Box<dyn Renderer>> {
    let mut renderer = spec.build(Arc::clone(scene), &config.options)?;
    renderer.prepare(config.width, config.height)?;
    Ok(renderer)
}

/// Renderers a comparison builds: the line-up's, and the reference's second instance
/// ([`Checker`]) when frames are checked.
fn lineup_builds(lineup: &Lineup) -> usize {
    lineup.entries.len() + usize::from(lineup.reference_label.is_some())
}

/// Builds every renderer of the line-up (preprocessing, timed), in order.
fn build(
    scene: &Arc<Scene>,
    config: &CompareConfig,
    lineup: &Lineup,
    progress: &mut dyn FnMut(CompareProgress),
) -> Result<Vec<Contestant>> {
    let count = lineup_builds(lineup);
    let mut contestants = Vec::with_capacity(count);
    for (index, (spec, requested)) in lineup.entries.iter().enumerate() {
        let label = spec.label();
        progress(CompareProgress::Building {
            label: &label,
            index,
            count,
        });
        let ((renderer, prepare_ms), peak_rss_bytes) = within_peak_window(config.peak_rss.as_ref(), || {
            let t = Instant::now();
            let renderer = build_prepared(spec, scene, config);
            (renderer, ms(t.elapsed()))
        });
        let renderer = renderer.map_err(|source| CompareError::Build {
            algorithm: label.clone(),
            source,
        })?;
        if lineup.reference_label.as_deref() == Some(label.as_str()) && !renderer.is_conservative() {
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
            spec: spec.clone(),
            label,
            requested: *requested,
            memory_bytes_after_build: renderer.memory_bytes(),
            peak_rss_bytes,
            renderer,
            frame: Frame::new(config.width, config.height)?,
            prepare_ms,
            records: Vec::new(),
            stats: Vec::new(),
        });
    }
    Ok(contestants)
}

/// Renders `view` with every renderer, the order rotated by `view_index` so that no renderer
/// always runs first (or right after another), and records each frame's time and counts.
fn render_view(contestants: &mut [Contestant], view: &View, view_index: usize, rss: Option<&PeakRss>) -> Result<()> {
    let n = contestants.len();
    for k in 0..n {
        let c = &mut contestants[(k + view_index) % n];
        let ((stats, time_ms), peak) = within_peak_window(rss, || {
            let t = Instant::now();
            let stats = c.renderer.render(view, &mut c.frame);
            (stats, ms(t.elapsed()))
        });
        let stats = stats.map_err(|source| CompareError::Render {
            algorithm: c.label.clone(),
            view_index,
            source,
        })?;
        c.peak_rss_bytes = c.peak_rss_bytes.zip(peak).map(|(a, b)| a.max(b));
        c.records.push(FrameRecord {
            time_ms,
            triangles_submitted: stats.triangles_submitted,
            triangles_rasterized: stats.triangles_rasterized,
            counters: stats.counters.clone(),
            ..FrameRecord::default()
        });
        c.stats.push(stats);
    }
    Ok(())
}

/// What the run measures besides the renderers' own records: the image of every view, each
/// frame against the reference's, and the oracle.
struct Checks {
    oracle: Oracle,
    oracle_frame: Frame,
    shaded_reference: Frame,
    oracle_times: Vec<f64>,
    oracle_identical: usize,
    image: ImageMeasures,
    /// The items visible in the measured frame of the current view, sorted.
    visible: Vec<ItemId>,
    /// Options of the supersampled reference.
    options: RenderOptions,
    /// The supersampled reference of the paper's criterion ([`oracle::paper_error`]): made
    /// when a frame first differs from the reference.
    fine: Option<(Box<dyn Renderer>, Frame)>,
    /// Whether to make [`Checks::diffs`] ([`CompareConfig::diff_images`]).
    diff_images: bool,
    /// The current view's images of differing frames, by renderer label.
    diffs: Vec<(String, image::RgbaImage)>,
}

impl Checks {
    /// Frames and oracle for `config`, measuring the images on `measured_on`'s frames.
    fn new(config: &CompareConfig, measured_on: &str, view_count: usize) -> Result<Self> {
        Ok(Self {
            oracle: Oracle::new(&config.options)?,
            oracle_frame: Frame::new(config.width, config.height)?,
            shaded_reference: Frame::new(config.width, config.height)?,
            oracle_times: Vec::with_capacity(view_count),
            oracle_identical: 0,
            image: ImageMeasures {
                measured_on: measured_on.to_string(),
                covered_pixels: Vec::with_capacity(view_count),
                triangles_visible: Vec::with_capacity(view_count),
                projected_pixels: config.image_complexity.then(|| Vec::with_capacity(view_count)),
            },
            visible: Vec::new(),
            options: config.options.clone(),
            fine: None,
            diff_images: config.diff_images,
            diffs: Vec::new(),
        })
    }

    /// Renders the supersampled reference of `view` ([`oracle::SUPERSAMPLE`] times the frame's
    /// size on each axis, smaller where that would exceed [`oracle::MAX_FINE_PIXELS`]).
    fn draw_fine(&mut self, scene: &Arc<Scene>, view: &View, view_index: usize) -> Result<()> {
        let label = "zbuffer (supersampled, the paper's criterion)";
        let (w, h) = oracle::fine_size(view.width(), view.height());
        let fits = |f: &Frame| f.width() == w && f.height() == h;
        if !self.fine.as_ref().is_some_and(|(_, f)| fits(f)) {
            let r = Algorithm::ZBUFFER
                .build(scene.clone(), &self.options)
                .map_err(|source| CompareError::Build {
                    algorithm: label.into(),
                    source,
                })?;
            self.fine = Some((r, Frame::new(w, h)?));
        }
        let fine_view =
            View::new(*view.camera(), w, h).map_err(|source| CompareError::BadView { view_index, source })?;
        let (r, f) = self.fine.as_mut().expect("made above");
        r.render(&fine_view, f).map_err(|source| CompareError::Render {
            algorithm: label.into(),
            view_index,
            source,
        })?;
        Ok(())
    }

    /// The image measures of `view` from `measured_frame` (the reference's or the first
    /// renderer's).
    fn measure_image(&mut self, scene: &Scene, view: &View, measured_frame: &Frame) {
        self.visible = measured_frame.visible_items();
        self.image.covered_pixels.push(measured_frame.covered_pixel_count());
        self.image.triangles_visible.push(self.visible.len() as u64);
        if let Some(p) = &mut self.image.projected_pixels {
            p.push(image_complexity(scene, view));
        }
    }

    /// Compares every renderer's frame of `view` with the reference frame (identical, or item
    /// error and PSNR of the shaded colors), then times the oracle on the visible set.
    ///
    /// # Errors
    /// [`CompareError::Build`] or [`CompareError::Render`] of the supersampled reference.
    fn check_view(
        &mut self,
        scene: &Arc<Scene>,
        view: &View,
        view_index: usize,
        contestants: &mut [Contestant],
        reference_frame: &Frame,
    ) -> Result<()> {
        let mut reference_shaded = false;
        let mut fine_drawn = false;
        for c in contestants.iter_mut() {
            let record = c.records.last_mut().expect("a record was just pushed");
            if c.frame.same_visibility(reference_frame) {
                record.identical = true;
                continue;
            }
            record.item_error = Some(item_error(&c.frame, reference_frame));
            if !fine_drawn {
                self.draw_fine(scene, view, view_index)?;
                fine_drawn = true;
            }
            if let Some((_, fine)) = &self.fine {
                record.paper_error = Some(oracle::paper_error(&c.frame, reference_frame, fine));
            }
            if !reference_shaded {
                self.shaded_reference.clone_from(reference_frame);
                shade(&mut self.shaded_reference, scene, view);
                reference_shaded = true;
            }
            shade(&mut c.frame, scene, view);
            let psnr = c.frame.color_psnr(&self.shaded_reference);
            record.psnr_db = psnr.is_finite().then_some(psnr);
            if let (true, Some((_, fine))) = (self.diff_images, &self.fine) {
                let image = oracle::diff_image(&c.frame, reference_frame, fine, &self.shaded_reference);
                self.diffs.push((c.label.clone(), image));
            }
        }
        // The oracle, from the reference's item buffer.
        let time_ms = self.oracle.render(scene, view, &self.visible, &mut self.oracle_frame);
        self.oracle_times.push(time_ms);
        if self.oracle_frame.same_visibility(reference_frame) {
            self.oracle_identical += 1;
        }
        Ok(())
    }
}

/// The report: every contestant's summary, the oracle's, the image measures.
fn report(
    scene: &Scene,
    config: &CompareConfig,
    lineup: Lineup,
    contestants: Vec<Contestant>,
    reference_index: Option<usize>,
    checks: Checks,
) -> CompareReport {
    let image = checks.image;
    let oracle = reference_index.map(|_| {
        let time = TimeSummary::of(&checks.oracle_times);
        OracleReport {
            mean_ms: time.mean_ms,
            p95_ms: time.p95_ms,
            time,
            frames_identical: checks.oracle_identical,
            per_frame_ms: checks.oracle_times,
            triangles_visible: image.triangles_visible.clone(),
        }
    });
    let baselines = Baselines {
        oracle_mean: oracle.as_ref().map_or(0.0, |o| o.mean_ms),
        zbuffer_mean: contestants
            .iter()
            .find(|c| c.spec.algorithm == Algorithm::ZBUFFER)
            .map(|c| TimeSummary::of(&c.records.iter().map(|r| r.time_ms).collect::<Vec<_>>()).mean_ms),
        visible_total: image.triangles_visible.iter().sum(),
        checked: reference_index.is_some(),
    };
    let renderers = contestants
        .into_iter()
        .enumerate()
        .map(|(i, c)| renderer_report(c, Some(i) == reference_index, &baselines))
        .collect();
    CompareReport {
        width: config.width,
        height: config.height,
        frames: image.covered_pixels.len(),
        scene_triangles: scene.item_count(),
        scene_memory_bytes: scene.memory_bytes(),
        threads: match config.options.raster.threads {
            0 => rayon::current_num_threads(),
            n => n,
        },
        reference: lineup.reference_label,
        reference_note: lineup.reference_note,
        oracle,
        image,
        renderers,
        skipped: lineup.skipped,
        process_peak_rss_bytes: config.peak_rss.as_ref().and_then(PeakRss::process_peak_bytes),
    }
}

/// What every renderer's summary is measured against.
struct Baselines {
    /// The oracle's mean time, ms (0 without an oracle).
    oracle_mean: f64,
    /// `zbuffer`'s mean time, ms, when it took part.
    zbuffer_mean: Option<f64>,
    /// Exactly visible triangles summed over the views.
    visible_total: u64,
    /// Whether frames were checked against a reference.
    checked: bool,
}

/// One contestant's summary.
fn renderer_report(c: Contestant, is_reference: bool, b: &Baselines) -> RendererReport {
    let frames = c.records.len();
    let times: Vec<f64> = c.records.iter().map(|r| r.time_ms).collect();
    let time = TimeSummary::of(&times);
    let ratio = |num: f64, den: f64| (den > 0.0 && num.is_finite()).then(|| num / den);
    let errors: Vec<f64> = c.records.iter().map(|r| r.item_error.unwrap_or(0.0)).collect();
    RendererReport {
        name: c.label,
        is_reference,
        requested: c.requested,
        conservative: c.renderer.is_conservative(),
        frames,
        frames_identical: b.checked.then(|| c.records.iter().filter(|r| r.identical).count()),
        mean_ms: time.mean_ms,
        p95_ms: time.p95_ms,
        speedup_vs_zbuffer: b.zbuffer_mean.and_then(|z| ratio(z, time.mean_ms)),
        vs_oracle: ratio(time.mean_ms, b.oracle_mean),
        triangles_rasterized: mean(c.records.iter().map(|r| r.triangles_rasterized as f64), frames),
        triangles_rasterized_total: c.records.iter().map(|r| r.triangles_rasterized).sum(),
        triangles_visible: b.visible_total as f64 / frames as f64,
        triangles_visible_total: b.visible_total,
        prepare_ms: c.prepare_ms,
        memory_bytes: c.renderer.memory_bytes(),
        memory_bytes_after_build: c.memory_bytes_after_build,
        peak_rss_bytes: c.peak_rss_bytes,
        mean_item_error: mean(errors.iter().copied(), frames),
        mean_paper_error: mean(c.records.iter().map(|r| r.paper_error.unwrap_or(0.0)), frames),
        max_item_error: errors.iter().copied().fold(0.0, f64::max),
        min_psnr_db: c.records.iter().filter_map(|r| r.psnr_db).reduce(f64::min),
        phases: phase_means(&c.stats),
        stats: mean_stats(&c.stats),
        time,
        per_frame: c.records,
    }
}
