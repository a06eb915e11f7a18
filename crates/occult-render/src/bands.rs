//! Sort-first rendering: a frame drawn as bands of rows, each by its own copy of a renderer on
//! its own thread (the setting `bands=N` of every renderer whose registry entry allows it).
//!
//! A culling renderer's frame is serial where it costs: its walk tests boxes one after the
//! other against the depth drawn so far, and the batches between two tests are too small to
//! share over the rasterizer's threads (handing a batch over costs more than it saves). On two
//! cores a culled frame runs on one while a frame drawn directly shares its large draws over
//! both, and culling must first win back that factor. With `bands=N`, each of N threads draws
//! a band of the screen's rows:
//!
//! - a view restricted to those rows ([`View::with_rows`]): the same camera, projection and
//!   resolution, a frustum holding only what can reach the band, and a rasterizer that writes
//!   no other row, so every pixel of the band comes out as in the whole view;
//! - a renderer of its own, built from the same settings with a one-thread rasterizer: its own
//!   hierarchies, depth structures, temporal state and frame-level choice between culling and
//!   drawing directly ([`crate::direct`]), all for its band;
//! - a frame of its own, whose other rows stay clear (only the band's rows are cleared per
//!   frame, [`occult_raster::Rasterizer::clear_rows`]); its rows are copied into the frame
//!   asked for.
//!
//! The frame is the whole view's, identical to `zbuffer`'s for a conservative renderer: each
//! band's rows hold the nearest fragment of everything that reaches them, and a box culled
//! against a band's depth (nearer than or as near as the whole frame's at every pixel it
//! covers) hides nothing of the band.
//!
//! Bands are balanced: after each frame, the rows are shared again so that each band's rows
//! per millisecond would take the same time, moving half way there (one noisy frame moves
//! them little); no band gets fewer than [`MIN_BAND_ROWS`] rows.
//!
//! Costs: what crosses two bands is walked and tested in both, its triangles set up twice
//! (each band scanning only its own rows); memory is the renderer's structures N times over,
//! plus a frame per band. Statistics add the bands' counts and counters (a triangle drawn in
//! two bands counts twice) and their phase times (thread time: together more than the frame's
//! wall time); counter `bands` gives the bands of the frame.

use std::sync::Arc;
use std::time::{Duration, Instant};

use occult_core::{Scene, View};
use occult_raster::Frame;

use crate::{AlgoSpec, FrameStats, ParamDoc, RenderError, RenderOptions, Renderer, Result};

/// The setting, documented with every renderer that takes it.
pub const BANDS_PARAM: ParamDoc = ParamDoc {
    key: "bands",
    default: "1",
    help: "sort-first: draw each frame as this many bands of rows (1..=64), each on its own thread with its own copy of the renderer and a one-thread rasterizer; 1 draws the whole frame at once",
};

/// Most bands a frame is split into.
pub const MAX_BANDS: usize = 64;

/// Fewest rows a band is given (unless the frame has fewer than this per band).
pub const MIN_BAND_ROWS: u32 = 8;

/// The counter of the bands a frame was drawn as.
pub const COUNTER: &str = "bands";

/// The bands `spec` asks for (its `bands`, 1 without one).
///
/// # Errors
/// [`RenderError::BadParameter`] for a count outside `1..=`[`MAX_BANDS`], or more than one band
/// of a renderer that cannot split (its frames are not drawn through the rasterizer alone).
pub(crate) fn bands(spec: &AlgoSpec) -> Result<usize> {
    let info = spec.algorithm.info();
    let n: usize = spec.params.get(BANDS_PARAM.key, 1)?;
    if n == 0 || n > MAX_BANDS {
        return Err(RenderError::BadParameter(format!(
            "{}: bands={n}: expected 1 to {MAX_BANDS}",
            info.name
        )));
    }
    if n > 1 && !info.bands {
        return Err(RenderError::BadParameter(format!(
            "{}: bands={n}: {} cannot draw a frame as bands of rows (it writes pixels other than through the rasterizer)",
            info.name, info.name
        )));
    }
    Ok(n)
}

/// A renderer drawing each frame as bands of rows ([module doc](self)).
pub struct Bands {
    name: &'static str,
    parts: Vec<Part>,
    /// Rows of each band in the last frame (empty before the first, or after a change of
    /// height).
    rows: Vec<u32>,
}

/// One band's renderer and frame.
struct Part {
    renderer: Box<dyn Renderer>,
    frame: Option<Frame>,
}

impl Bands {
    /// `n` copies of the renderer `spec` names (its `bands` aside), each with a one-thread
    /// rasterizer, built in parallel.
    ///
    /// # Errors
    /// The first error of a copy's build.
    pub(crate) fn build(scene: Arc<Scene>, options: &RenderOptions, spec: &AlgoSpec, n: usize) -> Result<Self> {
        let mut inner = options.clone();
        inner.raster.threads = 1;
        let mut params = crate::Params::new(spec.algorithm.name());
        for (k, v) in spec.params.entries().iter().filter(|(k, _)| k != BANDS_PARAM.key) {
            params.set(k, v);
        }
        let build = spec.algorithm.info().build;
        let (inner, params) = (&inner, &params);
        let built = on_threads((0..n).map(|_| scene.clone()).collect(), |scene| {
            build(scene, inner, params)
        });
        let parts = built
            .into_iter()
            .map(|r| r.map(|renderer| Part { renderer, frame: None }))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            name: spec.algorithm.name(),
            parts,
            rows: Vec::new(),
        })
    }

    /// The rows of each band for a frame of `height` rows: last frame's, or shared evenly.
    fn band_rows(&mut self, height: u32) -> Vec<std::ops::Range<u32>> {
        let n = self.parts.len().min(height as usize).max(1);
        if self.rows.len() != n || self.rows.iter().sum::<u32>() != height {
            self.rows = (0..n as u32)
                .map(|k| (k + 1) * height / n as u32 - k * height / n as u32)
                .collect();
        }
        let mut first = 0;
        self.rows
            .iter()
            .map(|&r| {
                first += r;
                first - r..first
            })
            .collect()
    }

    /// Shares the rows again from the bands' times: each band's rows per nanosecond say what
    /// rows would take them all the same time; every band moves half way there.
    fn balance(&mut self, times: &[Duration]) {
        let height: u32 = self.rows.iter().sum();
        let n = self.rows.len() as u32;
        let floor = MIN_BAND_ROWS.min(height / n.max(1)).max(1);
        let speed: Vec<f64> = self
            .rows
            .iter()
            .zip(times)
            .map(|(&r, t)| r as f64 / (t.as_nanos() as f64).max(1e3))
            .collect();
        let total: f64 = speed.iter().sum();
        let wanted: Vec<f64> = self
            .rows
            .iter()
            .zip(&speed)
            .map(|(&r, s)| (0.5 * r as f64 + 0.5 * height as f64 * s / total).max(floor as f64))
            .collect();
        // Rounded, the rest given to the bands in order so the rows add up to the height.
        let scale = (height - floor * n) as f64 / wanted.iter().map(|w| w - floor as f64).sum::<f64>().max(1e-9);
        let mut rows: Vec<u32> = wanted
            .iter()
            .map(|w| floor + ((w - floor as f64) * scale).floor() as u32)
            .collect();
        let left = height.saturating_sub(rows.iter().sum::<u32>());
        for k in 0..left as usize {
            rows[k % n as usize] += 1;
        }
        self.rows = rows;
    }
}

impl Renderer for Bands {
    fn name(&self) -> &'static str {
        self.name
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        crate::check_frame(view, frame)?;
        let start = Instant::now();
        let bands = self.band_rows(view.height());
        let (width, height) = (view.width(), view.height());
        for part in &mut self.parts[..bands.len()] {
            if part
                .frame
                .as_ref()
                .is_none_or(|f| f.width() != width || f.height() != height)
            {
                part.frame = Some(Frame::new(width, height)?);
            }
        }
        let w = width as usize;
        let (depth, items) = frame.buffers_mut();
        // Each band's rows of the frame asked for, for its thread to copy its own into.
        let mut targets = Vec::with_capacity(bands.len());
        let (mut depth, mut items) = (depth, items);
        for rows in &bands {
            let len = (rows.end - rows.start) as usize * w;
            let (d, rest_d) = depth.split_at_mut(len);
            let (i, rest_i) = items.split_at_mut(len);
            targets.push((d, i));
            (depth, items) = (rest_d, rest_i);
        }
        let draw = |part: &mut Part, rows: std::ops::Range<u32>, (d, i): (&mut [f32], &mut [occult_core::ItemId])| {
            let t = Instant::now();
            let band = view
                .with_rows(rows.clone())
                .expect("bands are non-empty rows of the view");
            let own = part.frame.as_mut().expect("made above");
            let stats = part.renderer.render(&band, own)?;
            let span = rows.start as usize * w..rows.end as usize * w;
            d.copy_from_slice(&own.depth()[span.clone()]);
            i.copy_from_slice(&own.items()[span]);
            Ok((stats, t.elapsed()))
        };
        let work = self.parts.iter_mut().zip(bands.iter().cloned()).zip(targets).collect();
        let results: Vec<Result<(FrameStats, Duration)>> =
            on_threads(work, |((part, rows), target)| draw(part, rows, target));
        let mut stats = FrameStats::default();
        let mut times = Vec::with_capacity(results.len());
        for r in results {
            let (s, t) = r?;
            stats.add_counts(&s);
            stats.rects_tested += s.rects_tested;
            stats.rects_culled += s.rects_culled;
            stats.rays_cast += s.rays_cast;
            stats.samples_drawn += s.samples_drawn;
            stats.phases.merge(&s.phases);
            stats.counters.merge(&s.counters);
            times.push(t);
        }
        stats.counters.add(COUNTER, bands.len() as u64);
        self.balance(&times);
        stats.total = start.elapsed();
        Ok(stats)
    }

    fn memory_bytes(&self) -> usize {
        self.parts
            .iter()
            .map(|p| p.renderer.memory_bytes() + p.frame.as_ref().map_or(0, Frame::memory_bytes))
            .sum()
    }

    fn is_conservative(&self) -> bool {
        self.parts[0].renderer.is_conservative()
    }
}

/// `job` of every item, the first on the calling thread and each other on a thread of its
/// own, in order; a panic of one is raised again here.
fn on_threads<T: Send, R: Send>(items: Vec<T>, job: impl Fn(T) -> R + Sync) -> Vec<R> {
    let job = &job;
    std::thread::scope(|s| {
        let mut items = items.into_iter();
        let Some(first) = items.next() else {
            return Vec::new();
        };
        let others: Vec<_> = items.map(|item| s.spawn(move || job(item))).collect();
        std::iter::once(job(first))
            .chain(
                others
                    .into_iter()
                    .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p))),
            )
            .collect()
    })
}
