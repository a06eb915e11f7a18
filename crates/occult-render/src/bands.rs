//! Sort-first rendering: a frame drawn as bands of columns, each by its own copy of a renderer
//! on its own thread (the setting `bands=N` of every renderer whose registry entry allows it).
//!
//! A culling renderer's frame is serial where it costs: its walk tests boxes one after the
//! other against the depth drawn so far, and the batches between two tests are too small to
//! share over the rasterizer's threads (handing a batch over costs more than it saves). On two
//! cores a culled frame runs on one while a frame drawn directly shares its large draws over
//! both, and culling must first win back that factor. With `bands=N`, each of N threads draws
//! a band of the screen's columns:
//!
//! - a view restricted to those columns ([`View::with_region`]): the same camera, projection
//!   and resolution, a frustum holding only what can reach the band, and a rasterizer that
//!   writes no other pixel and rejects a triangle wholly beside the band before its setup, so
//!   every pixel of the band comes out as in the whole view;
//! - a renderer of its own, built from the same settings with a one-thread rasterizer: its own
//!   hierarchies, depth structures, temporal state and frame-level choice between culling and
//!   drawing directly ([`crate::direct`]), all for its band;
//! - a frame of its own, whose other pixels hold [`occult_raster::BLOCKED_DEPTH`] (nearer than
//!   anything, [`occult_raster::Rasterizer::clear_region`]), so that every occlusion test,
//!   pyramid and query of the renderer judges a box by its pixels in the band alone; only the
//!   band is cleared per frame. Its columns are copied into the frame asked for.
//!
//! The frame is the whole view's, identical to `zbuffer`'s for a conservative renderer: each
//! band's pixels hold the nearest fragment of everything that reaches them, and a box culled
//! against a band's depth hides nothing of the band.
//!
//! Bands are columns, not rows: a view towards the horizon gathers most of its triangles in a
//! few rows (the distant part of a city, a forest or a terrain), which a split of the rows
//! leaves to one band (measured: one band idle for most of the frame); columns share them.
//! After each frame the cuts between bands move half way (one noisy frame moves them little)
//! towards an even split of the frame's cost, each band's time spread evenly over its columns;
//! no band gets fewer than [`MIN_BAND_COLUMNS`] columns ([`ColumnShare`]).
//!
//! Costs: what crosses two bands is walked and tested in both, its vertices projected twice;
//! memory is the renderer's structures N times over, plus a frame per band. Statistics add the
//! bands' counts and counters (a triangle drawn in two bands counts twice) and their phase
//! times (thread time: together more than the frame's wall time), with the copy into the frame
//! as `other`; a triangle within a pixel of a band counts as rasterized by it. Counter `bands`
//! gives the bands of the frame, `bands_idle_us` the time they waited for the slowest,
//! together. The bands share the frame's [`occult_raster::FrameControl`]: a cancel stops each
//! band at its next check (a band that fails leaves the others to finish, then its error is the
//! frame's), and the progress read is the furthest band's.

use std::sync::Arc;
use std::time::{Duration, Instant};

use occult_core::{Scene, View};
use occult_raster::Frame;

use crate::{AlgoSpec, FrameStats, ParamDoc, Phase, RenderError, RenderOptions, Renderer, Result};

/// The setting, documented with every renderer that takes it.
pub const BANDS_PARAM: ParamDoc = ParamDoc {
    key: "bands",
    default: "1",
    help: "sort-first: draw each frame as this many bands of columns (1..=64), each on its own thread with its own copy of the renderer and a one-thread rasterizer; 1 draws the whole frame at once",
};

/// Most bands a frame is split into.
pub const MAX_BANDS: usize = 64;

/// Fewest columns a band is given (unless the frame has fewer than this per band).
pub const MIN_BAND_COLUMNS: u32 = 8;

/// The counter of the bands a frame was drawn as.
pub const COUNTER: &str = "bands";
/// The counter of the time bands waited for the slowest one, together, µs: how far the
/// balance is off.
pub const IDLE: &str = "bands_idle_us";

/// The bands `spec` asks for (its `bands`, 1 without one).
///
/// # Errors
/// [`RenderError::BadParameter`] for a count outside `1..=`[`MAX_BANDS`], or more than one band
/// (a renderer that cannot draw bands has no such key: [`crate::AlgoSpec::check_keys`]).
pub(crate) fn bands(spec: &AlgoSpec) -> Result<usize> {
    let info = spec.algorithm.info();
    let n: usize = spec.params.get(BANDS_PARAM.key, 1)?;
    if n == 0 || n > MAX_BANDS {
        return Err(RenderError::BadParameter(format!(
            "{}: bands={n}: expected 1 to {MAX_BANDS}",
            info.name
        )));
    }
    Ok(n)
}

/// A renderer drawing each frame as bands of columns ([module doc](self)).
pub struct Bands {
    name: &'static str,
    /// The frames' cancellation and progress, shared by the bands' rasterizers.
    control: occult_raster::FrameControl,
    parts: Vec<Part>,
    columns: ColumnShare,
}

/// How the columns of a frame are shared between bands, frame after frame: evenly at first
/// (and again at a new width or count), then moved after each frame by
/// [`ColumnShare::balance`]; no band gets fewer than [`MIN_BAND_COLUMNS`] columns.
#[derive(Debug, Default)]
pub(crate) struct ColumnShare {
    /// Columns of each band in the last frame (empty before the first, or after a change of
    /// width or of the bands' count).
    columns: Vec<u32>,
}

impl ColumnShare {
    /// The columns of each of `n` bands (at most one a column) for a frame `width` pixels
    /// wide: last frame's, or shared evenly.
    pub(crate) fn ranges(&mut self, width: u32, n: usize) -> Vec<std::ops::Range<u32>> {
        let n = n.min(width as usize).max(1);
        if self.columns.len() != n || self.columns.iter().sum::<u32>() != width {
            self.columns = (0..n as u32)
                .map(|k| (k + 1) * width / n as u32 - k * width / n as u32)
                .collect();
        }
        let mut first = 0;
        self.columns
            .iter()
            .map(|&r| {
                first += r;
                first - r..first
            })
            .collect()
    }

    /// Shares the columns again from the time each band took last frame (in the bands' order):
    /// each band's time spread evenly over its columns gives a cost per column; the cuts that
    /// would split that cost evenly are found, and each cut moves half way there.
    pub(crate) fn balance(&mut self, times: &[Duration]) {
        let width: u32 = self.columns.iter().sum();
        let n = self.columns.len();
        if n < 2 || times.len() != n {
            return;
        }
        let floor = MIN_BAND_COLUMNS.min(width / n as u32).max(1);
        // Every column costs at least a hundredth of the mean, so that an empty band (the sky)
        // is not handed the whole screen next frame.
        let total: f64 = times.iter().map(|t| t.as_nanos() as f64).sum::<f64>().max(1.0);
        let least = 0.01 * total / width as f64;
        let density: Vec<f64> = self
            .columns
            .iter()
            .zip(times)
            .map(|(&c, t)| (t.as_nanos() as f64 / c.max(1) as f64).max(least))
            .collect();
        let cost: f64 = self.columns.iter().zip(&density).map(|(&c, d)| c as f64 * d).sum();
        // The old cuts and the even ones, as column positions.
        let mut cuts = Vec::with_capacity(n - 1);
        let (mut at, mut band, mut before) = (0.0f64, 0usize, 0.0f64);
        let mut old = 0u32;
        for j in 1..n {
            old += self.columns[j - 1];
            let wanted = cost * j as f64 / n as f64;
            while band < n - 1 && before + self.columns[band] as f64 * density[band] < wanted {
                before += self.columns[band] as f64 * density[band];
                at += self.columns[band] as f64;
                band += 1;
            }
            let even = at + (wanted - before) / density[band];
            cuts.push(0.5 * old as f64 + 0.5 * even);
        }
        // Rounded, each band keeping at least `floor` columns.
        let mut columns = Vec::with_capacity(n);
        let mut left = 0u32;
        for (j, &c) in cuts.iter().enumerate() {
            let lo = left + floor;
            let hi = width - floor * (n - 1 - j) as u32;
            let cut = (c.round() as u32).clamp(lo, hi.max(lo));
            columns.push(cut - left);
            left = cut;
        }
        columns.push(width - left);
        self.columns = columns;
    }
}

/// Copies the columns `c` of each `(source, c)` into `frame` (all of one size), the rows shared
/// over as many threads as there are sources.
pub(crate) fn assemble(frame: &mut Frame, sources: &[(&Frame, std::ops::Range<usize>)]) {
    let (w, height) = (frame.width() as usize, frame.height() as usize);
    let (depth, items) = frame.buffers_mut();
    let rows_each = height.div_ceil(sources.len().max(1)).max(1) * w;
    let chunks = depth
        .chunks_mut(rows_each)
        .zip(items.chunks_mut(rows_each))
        .enumerate()
        .collect();
    on_threads(
        chunks,
        |(k, (d, i)): (usize, (&mut [f32], &mut [occult_core::ItemId]))| {
            for (row, (d, i)) in d.chunks_mut(w).zip(i.chunks_mut(w)).enumerate() {
                let at = (k * rows_each / w + row) * w;
                for (own, c) in sources {
                    d[c.clone()].copy_from_slice(&own.depth()[at + c.start..at + c.end]);
                    i[c.clone()].copy_from_slice(&own.items()[at + c.start..at + c.end]);
                }
            }
        },
    );
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
            control: options.raster.control.clone(),
            parts,
            columns: ColumnShare::default(),
        })
    }
}

impl Renderer for Bands {
    fn name(&self) -> &'static str {
        self.name
    }

    fn render(&mut self, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        crate::check_frame(view, frame)?;
        let start = Instant::now();
        let bands = self.columns.ranges(view.width(), self.parts.len());
        let (width, height) = (view.width(), view.height());
        let draw = |part: &mut Part, columns: std::ops::Range<u32>| {
            let t = Instant::now();
            let band = view
                .with_region(columns, 0..height)
                .expect("bands are non-empty columns of the view");
            // A band's frame is made by its own thread (at the first frame, or a new size).
            if part
                .frame
                .as_ref()
                .is_none_or(|f| f.width() != width || f.height() != height)
            {
                part.frame = Some(Frame::new(width, height)?);
            }
            let own = part.frame.as_mut().expect("made above");
            let stats = part.renderer.render(&band, own)?;
            Ok((stats, t.elapsed()))
        };
        let work = self.parts.iter_mut().zip(bands.iter().cloned()).collect();
        let results: Vec<Result<(FrameStats, Duration)>> = on_threads(work, |(part, columns)| draw(part, columns));
        if self.control.is_cancelled() {
            return Err(RenderError::Cancelled);
        }
        // Each band's columns into the frame asked for.
        let t = Instant::now();
        let sources: Vec<(&Frame, std::ops::Range<usize>)> = self
            .parts
            .iter()
            .zip(&bands)
            .filter_map(|(p, c)| Some((p.frame.as_ref()?, c.start as usize..c.end as usize)))
            .collect();
        assemble(frame, &sources);
        let assembled = t.elapsed();
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
        let slowest = times.iter().max().copied().unwrap_or_default();
        let idle: Duration = times.iter().map(|&t| slowest - t).sum();
        stats.counters.add(IDLE, idle.as_micros() as u64);
        stats.phases.add(Phase::Other, assembled);
        self.columns.balance(&times);
        stats.total = start.elapsed();
        Ok(stats)
    }

    /// Each band's frame and its renderer's own preparation, on the band's thread (as its first
    /// frame would make them).
    fn prepare(&mut self, width: u32, height: u32) -> Result<()> {
        let work = self.parts.iter_mut().collect();
        let results: Vec<Result<()>> = on_threads(work, |part: &mut Part| {
            if part
                .frame
                .as_ref()
                .is_none_or(|f| f.width() != width || f.height() != height)
            {
                part.frame = Some(Frame::new(width, height)?);
            }
            part.renderer.prepare(width, height)
        });
        results.into_iter().collect()
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
pub(crate) fn on_threads<T: Send, R: Send>(items: Vec<T>, job: impl Fn(T) -> R + Sync) -> Vec<R> {
    let job = &job;
    std::thread::scope(|s| {
        let mut items = items.into_iter();
        let Some(first) = items.next() else {
            return Vec::new();
        };
        // A thread that cannot start leaves its item to the calling thread, after its own.
        let others: Vec<_> = items
            .map(|item| {
                let item = std::sync::Arc::new(std::sync::Mutex::new(Some(item)));
                let mine = std::sync::Arc::clone(&item);
                let take = move || mine.lock().unwrap_or_else(std::sync::PoisonError::into_inner).take();
                let spawned = std::thread::Builder::new().spawn_scoped(s, move || take().map(job));
                (item, spawned.ok())
            })
            .collect();
        let mut results = vec![job(first)];
        for (item, handle) in others {
            let done = handle.and_then(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
            let left = || item.lock().unwrap_or_else(std::sync::PoisonError::into_inner).take();
            results.push(done.unwrap_or_else(|| job(left().expect("an item not taken by a thread that ran"))));
        }
        results
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: &[u64]) -> Vec<Duration> {
        v.iter().map(|&m| Duration::from_millis(m)).collect()
    }

    /// The cuts move towards splitting the cost evenly, half way a frame; an empty band is not
    /// handed the whole screen; the columns always add up to the width, none below the floor.
    #[test]
    fn columns_move_towards_even_cost() {
        let mut c = ColumnShare::default();
        assert_eq!(c.ranges(1280, 4), vec![0..320, 320..640, 640..960, 960..1280]);
        // The cost lies in the middle two bands (a city in the middle of the screen).
        c.balance(&ms(&[0, 100, 100, 0]));
        let r = c.ranges(1280, 4);
        assert_eq!(r.last().map(|r| r.end), Some(1280));
        let widths: Vec<u32> = r.iter().map(|r| r.end - r.start).collect();
        assert!(widths[0] > 320 && widths[3] > 320, "{widths:?}");
        assert!(widths[1] < 320 && widths[2] < 320, "{widths:?}");
        assert!(widths[0] < 640, "half way, not all the way: {widths:?}");
        // Again and again: it settles with the middle bands narrow, never an empty band.
        for _ in 0..20 {
            let r = c.ranges(1280, 4);
            // Time as the columns of the middle 640 each band holds.
            let times: Vec<u64> = r
                .iter()
                .map(|r| (r.end.min(960).saturating_sub(r.start.max(320))) as u64 + 1)
                .collect();
            c.balance(&ms(&times));
            let w: Vec<u32> = c.ranges(1280, 4).iter().map(|r| r.end - r.start).collect();
            assert_eq!(w.iter().sum::<u32>(), 1280);
            assert!(w.iter().all(|&w| w >= MIN_BAND_COLUMNS), "{w:?}");
        }
        let r = c.ranges(1280, 4);
        assert!(
            r[0].end > 320 && r[3].start < 960 && r[1].end < 700 && r[2].start > 580,
            "{r:?}"
        );
        // Two bands of equal cost stay as they are; one band alone is never moved.
        let mut two = ColumnShare::default();
        let before = two.ranges(100, 2);
        two.balance(&ms(&[5, 5]));
        assert_eq!(two.ranges(100, 2), before);
        let mut one = ColumnShare::default();
        one.ranges(10, 1);
        one.balance(&ms(&[7]));
        assert_eq!(one.ranges(10, 1), vec![0..10]);
    }
}
