//! Sort-first by columns within one renderer (`parallel=columns` of `hzb` and `oqgrid`; not in
//! their papers): a culled frame drawn on every thread.
//!
//! A culled frame is serial where it costs: its walk tests boxes one after the other against
//! the depth drawn so far, and the batches between two tests are too small for the
//! rasterizer to share over its threads. Under the columns distribution the screen is cut into
//! `workers × strips` strips of columns, handed out one at a time (last frame's slowest first)
//! to whichever worker is free. A worker culls and draws a strip as a view restricted to its
//! columns ([`View::with_region`]), into its own frame (cleared over the strip, blocked beside
//! it, so that every test judges a box by the strip's pixels alone) with its own depth
//! structures and a one-thread rasterizer, with the strip's own temporal state and in-frame
//! payoff (`Strip`); then it copies the strip's columns into the frame asked for (no merge:
//! each pixel is drawn by one strip). Unlike [`crate::bands`], which copies the whole renderer
//! per band, the workers share the renderer's hierarchies, and the frame-level choice between
//! culling and drawing directly ([`crate::direct`]) is the renderer's: a direct frame is drawn
//! whole, on all threads. After each frame the cuts move towards an even split of the strips'
//! times (`bands::ColumnShare`).
//!
//! Statistics add the strips' counts and counters (a triangle drawn in two strips counts twice)
//! and their phases (thread time: together more than the frame's wall time), with the copies
//! as `other`; counter [`STRIPS`] gives the strips of the frame, [`BUSY`] and [`IDLE`] each
//! worker's time at work and waiting for the slowest.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use occult_core::View;
use occult_raster::{Frame, Rasterizer};

use crate::direct::DirectFrames;
use crate::payoff::Payoff;
use crate::{FrameStats, Phase, RenderError, Result};

/// Triangle instances from which `parallel=auto` chooses the columns distribution. The
/// strips' fixed part (a second frame cleared, the columns copied, the upper levels of the
/// hierarchy walked per strip) is about a millisecond a frame at 1280x720; it pays on the
/// suite's scenes of 9-45 M triangles (frames of 60-190 ms with `zbuffer`) and not on those of
/// 1-5 M.
pub const AUTO_COLUMNS: u64 = 8_000_000;

/// Whether a renderer's `parallel=auto` takes the columns distribution for `scene` drawn on
/// `threads` threads: scenes of at least [`AUTO_COLUMNS`] triangle instances, two threads or
/// more.
pub fn auto_takes_columns(scene: &occult_core::Scene, threads: usize) -> bool {
    scene.item_count() >= AUTO_COLUMNS && threads >= 2
}

/// Most workers of a distribution.
pub const MAX_WORKERS: usize = 8;

/// Most strips of columns a worker.
pub const MAX_STRIPS: usize = 16;

/// The counter of the strips of columns a frame was drawn as.
pub const STRIPS: &str = "strips";

/// Counter names per worker of its time at work in the frame, µs (counters are named by static
/// strings).
pub const BUSY: [&str; MAX_WORKERS] = [
    "worker0_busy_us",
    "worker1_busy_us",
    "worker2_busy_us",
    "worker3_busy_us",
    "worker4_busy_us",
    "worker5_busy_us",
    "worker6_busy_us",
    "worker7_busy_us",
];
/// Counter names per worker of its time waiting for the slowest, µs.
pub const IDLE: [&str; MAX_WORKERS] = [
    "worker0_idle_us",
    "worker1_idle_us",
    "worker2_idle_us",
    "worker3_idle_us",
    "worker4_idle_us",
    "worker5_idle_us",
    "worker6_idle_us",
    "worker7_idle_us",
];

/// A renderer's `counters` (with [`STRIPS`] among them) followed by the workers' [`BUSY`] and
/// [`IDLE`]: every counter it may report under the columns distribution, for its registry
/// entry (`N` = `counters.len() + 2 *` [`MAX_WORKERS`], checked when it is evaluated).
pub(crate) const fn declared<const N: usize>(counters: &[&'static str]) -> [&'static str; N] {
    assert!(
        counters.len() + 2 * MAX_WORKERS == N,
        "N: the counters and two a worker"
    );
    let mut all = [""; N];
    let mut i = 0;
    while i < counters.len() {
        all[i] = counters[i];
        i += 1;
    }
    let mut k = 0;
    while k < MAX_WORKERS {
        all[i + k] = BUSY[k];
        all[i + MAX_WORKERS + k] = IDLE[k];
        k += 1;
    }
    all
}

/// What one strip of columns keeps from frame to frame, whichever worker draws it: the
/// renderer's own temporal state `S` and the strip's payoff.
pub(crate) struct Strip<S> {
    pub(crate) state: S,
    pub(crate) payoff: Payoff,
    /// How long it took last frame (after the one-time setup of the worker that drew it).
    time: Duration,
}

/// A worker of the distribution: its one-thread rasterizer and the frame it draws strips into.
pub(crate) trait StripWorker: Send {
    /// Its rasterizer (one thread).
    fn raster(&mut self) -> &mut Rasterizer;
    /// Makes its frame and depth structures for a frame of `width × height` where it has none
    /// of that size; true when it made them (a one-time cost).
    ///
    /// # Errors
    /// Allocation refused.
    fn ready(&mut self, width: u32, height: u32) -> Result<bool>;
    /// The frame it draws strips into (made by [`StripWorker::ready`]).
    fn frame(&self) -> &Frame;
}

/// The strips of a renderer's columns distribution ([module doc](self)).
pub(crate) struct Columns<S> {
    strips: Vec<Mutex<Strip<S>>>,
    share: crate::bands::ColumnShare,
}

impl<S: Send> Columns<S> {
    /// `count` strips, each with the state and payoff `make` gives.
    pub(crate) fn new(count: usize, mut make: impl FnMut() -> (S, Payoff)) -> Self {
        Self {
            strips: (0..count)
                .map(|_| {
                    let (state, payoff) = make();
                    Mutex::new(Strip {
                        state,
                        payoff,
                        time: Duration::ZERO,
                    })
                })
                .collect(),
            share: crate::bands::ColumnShare::default(),
        }
    }

    /// Every strip, for what a renderer reads or sets in each (memory, tests).
    pub(crate) fn strips_mut(&mut self) -> impl Iterator<Item = &mut Strip<S>> {
        self.strips
            .iter_mut()
            .map(|s| s.get_mut().unwrap_or_else(PoisonError::into_inner))
    }

    /// Bytes held by the strips' states, by `bytes` of each.
    pub(crate) fn memory_bytes(&self, bytes: impl Fn(&S) -> usize) -> usize {
        self.strips
            .iter()
            .map(|s| bytes(&s.lock().unwrap_or_else(PoisonError::into_inner).state))
            .sum()
    }

    /// The views of this frame's strips: `view` restricted to each strip's columns (fewer
    /// strips than columns only on a frame narrower than the strips' count).
    ///
    /// # Errors
    /// [`RenderError::BadParameter`] naming `who` when a restricted view cannot be made.
    pub(crate) fn views(&mut self, view: &View, who: &str) -> Result<Vec<View>> {
        let first = view.columns().start;
        self.share
            .ranges(view.columns().len() as u32, self.strips.len())
            .iter()
            .map(|c| view.with_region(first + c.start..first + c.end, view.rows()))
            .collect::<std::result::Result<Vec<View>, _>>()
            .map_err(|e| RenderError::BadParameter(format!("{who}: parallel=columns: {e}")))
    }

    /// Arms each strip's payoff against its share of a whole direct frame of `view`: the work
    /// in view by its share of the columns, on one thread, in the time a worker has for it (the
    /// direct frame's, over the strips each of `workers` draws).
    pub(crate) fn arm(&mut self, direct: &DirectFrames, view: &View, bands: &[View], workers: usize) {
        let (expected, work) = (direct.expected_ns(), direct.work());
        let width = view.columns().len().max(1) as f64;
        let per_worker = bands.len() as f64 / workers.max(1) as f64;
        for (strip, band) in self.strips_mut().zip(bands) {
            let share = band.columns().len() as f64 / width;
            strip
                .payoff
                .set_direct(expected.map(|e| e / per_worker), (work as f64 * share) as u64, 1);
        }
    }

    /// Whether the tests of the last frame's `n` strips paid, together
    /// ([`Payoff::paid_together`]).
    pub(crate) fn paid(&mut self, n: usize) -> bool {
        Payoff::paid_together(self.strips_mut().take(n).map(|s| &s.payoff))
    }

    /// Draws `frame` as the strips `bands` ([`Columns::views`]) over `workers` (at most
    /// [`MAX_WORKERS`]), each strip by `draw`, which begins the strip's frame in the worker's
    /// (made by [`StripWorker::ready`] before), culls and draws the strip's view into it and
    /// returns its statistics with every phase accounted for. Counters named in `means` are averaged over the strips
    /// that report them instead of added. Also returns how long making the workers' frames
    /// took (at the first frame or a new size; the slowest worker's): a one-time cost that the
    /// frame-level choice between culling and drawing directly should not weigh.
    ///
    /// # Errors
    /// A worker's error (the others finish their strips first); cancellation.
    pub(crate) fn render<W: StripWorker>(
        &mut self,
        workers: Vec<&mut W>,
        frame: &mut Frame,
        bands: &[View],
        means: &[&'static str],
        draw: impl Fn(&mut W, &mut Strip<S>, &View) -> Result<FrameStats> + Sync,
    ) -> Result<(FrameStats, Duration)> {
        debug_assert!(workers.len() <= MAX_WORKERS, "a counter name per worker");
        let strips = &self.strips[..];
        let (width, height) = (frame.width(), frame.height());
        // The slowest strips of last frame first (the longest jobs first balance best).
        let mut order: Vec<usize> = (0..bands.len()).collect();
        order.sort_by_key(|&k| std::cmp::Reverse(strips[k].lock().unwrap_or_else(PoisonError::into_inner).time));
        let next = AtomicUsize::new(0);
        let out = Mutex::new(&mut *frame);
        let copied = Mutex::new(Duration::ZERO);
        /// What a worker did: per strip drawn its statistics, its busy time, its setup.
        type Done = (Vec<FrameStats>, Duration, Duration);
        let job = |w: &mut W| -> Result<Done> {
            let t = Instant::now();
            let setup = if w.ready(width, height)? {
                t.elapsed()
            } else {
                Duration::ZERO
            };
            let mut done = Vec::new();
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(&k) = order.get(i) else { break };
                let band = &bands[k];
                let mut strip = strips[k].lock().unwrap_or_else(PoisonError::into_inner);
                let t = Instant::now();
                let stats = draw(w, &mut strip, band)?;
                strip.time = t.elapsed();
                let c = Instant::now();
                {
                    let mut out = out.lock().unwrap_or_else(PoisonError::into_inner);
                    copy_columns(&mut out, w.frame(), band.columns());
                }
                *copied.lock().unwrap_or_else(PoisonError::into_inner) += c.elapsed();
                done.push(stats);
                crate::check_cancel(w.raster())?;
            }
            Ok((done, t.elapsed(), setup))
        };
        let results = crate::bands::on_threads(workers, job);
        let results = results.into_iter().collect::<Result<Vec<_>>>()?;
        let slowest = results.iter().map(|r| r.1).max().unwrap_or_default();
        let mut stats = FrameStats::default();
        let mut averaged = vec![(0u64, 0u64); means.len()];
        for (k, (done, busy, _)) in results.iter().enumerate() {
            for s in done {
                stats.add_counts(s);
                stats.counters.merge(&s.counters);
                stats.phases.merge(&s.phases);
                for (name, sum) in means.iter().zip(&mut averaged) {
                    if s.counters.0.iter().any(|(c, _)| c == name) {
                        *sum = (sum.0 + s.counters.get(name), sum.1 + 1);
                    }
                }
            }
            stats.counters.add(BUSY[k], busy.as_micros() as u64);
            stats.counters.add(IDLE[k], (slowest - *busy).as_micros() as u64);
        }
        for (name, (sum, n)) in means.iter().zip(averaged) {
            if let Some((_, v)) = stats.counters.0.iter_mut().find(|(c, _)| c == name) {
                *v = sum / n.max(1);
            }
        }
        stats.counters.add(STRIPS, bands.len() as u64);
        stats.phases.add(
            Phase::Other,
            copied.into_inner().unwrap_or_else(PoisonError::into_inner),
        );
        // Strips in column order, each with its time.
        let times: Vec<Duration> = self.strips_mut().map(|s| s.time).collect();
        self.share.balance(&times);
        let setup = results.iter().map(|r| r.2).max().unwrap_or_default();
        Ok((stats, setup))
    }
}

/// Copies the pixels of `columns` of `from` into `out` (frames of one size).
fn copy_columns(out: &mut Frame, from: &Frame, columns: std::ops::Range<u32>) {
    let w = out.width() as usize;
    let c = columns.start as usize..columns.end as usize;
    let (depth, items) = out.buffers_mut();
    for (row, (d, i)) in depth.chunks_mut(w).zip(items.chunks_mut(w)).enumerate() {
        let at = row * w;
        d[c.clone()].copy_from_slice(&from.depth()[at + c.start..at + c.end]);
        i[c.clone()].copy_from_slice(&from.items()[at + c.start..at + c.end]);
    }
}
