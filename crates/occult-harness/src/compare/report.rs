//! What [`compare`](super::compare) returns, and the summaries it is made of.

use std::collections::BTreeMap;
use std::time::Duration;

use occult_render::{Counters, FrameStats, Phase};
use serde::Serialize;

#[cfg(doc)]
use super::{compare, CompareConfig};
#[cfg(doc)]
use occult_core::Scene;
#[cfg(doc)]
use occult_render::{Algorithm, Renderer};

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
    /// When not identical: the share of covered pixels that are wrong by the randomized
    /// z-buffer paper's criterion (§4.1: a pixel is correct when it shows a triangle visible
    /// somewhere in it; measured against a supersampled `zbuffer` frame, see
    /// `oracle::paper_error`). `None` when identical.
    pub paper_error: Option<f64>,
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
    pub counters: BTreeMap<&'static str, f64>,
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
    /// are included). `None` unless asked for ([`CompareConfig::peak_rss`]), or where it cannot
    /// be measured: not Linux, or the kernel's high-water mark could not be reset.
    pub peak_rss_bytes: Option<u64>,
    /// Mean share of differing covered pixels over all frames (0 for identical frames).
    pub mean_item_error: f64,
    /// Largest per-frame share of differing covered pixels.
    pub max_item_error: f64,
    /// Mean share of covered pixels wrong by the paper's criterion over all frames (0 for
    /// identical frames; see [`FrameRecord::paper_error`]).
    pub mean_paper_error: f64,
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
    /// scene, every renderer and everything else the process did; `None` unless asked for
    /// ([`CompareConfig::peak_rss`]) or where unavailable.
    pub process_peak_rss_bytes: Option<u64>,
}

impl CompareReport {
    /// The report of the renderer called `name`.
    pub fn renderer(&self, name: &str) -> Option<&RendererReport> {
        self.renderers.iter().find(|r| r.name == name)
    }
}

/// `d` in milliseconds.
pub(crate) fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// The sum of `values` over `count` (0 when `count` is 0).
pub(crate) fn mean(values: impl Iterator<Item = f64>, count: usize) -> f64 {
    if count == 0 {
        0.0
    } else {
        values.sum::<f64>() / count as f64
    }
}

/// The mean time of every phase that occurs in `stats`, in order of first occurrence.
pub(crate) fn phase_means(stats: &[FrameStats]) -> Vec<PhaseMean> {
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

/// Every counter of `stats`, averaged.
pub(crate) fn mean_stats(stats: &[FrameStats]) -> MeanStats {
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
            let mut sums = BTreeMap::new();
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
