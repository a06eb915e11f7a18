//! Whether occlusion tests pay, measured while a frame is drawn: a culling renderer stops
//! testing for the rest of a frame once its tests cost more than they save, and draws the rest
//! directly.
//!
//! A conservative renderer's tests are pure overhead on views where little is hidden (open
//! terrain, sparse foliage seen from outside). [`Payoff`] gives every such renderer the same
//! guarantee, measured rather than tuned. Within a frame it weighs
//!
//! - **cost**: the wall time spent so far outside rasterization (the tests, the walk that feeds
//!   them, the depth-structure updates they need), against
//! - **gain**: the triangles the tests removed, times the measured rasterization cost of a
//!   triangle (the renderer's own batches, this frame or, before its first batch, the last),
//!
//! and tells the renderer to stop testing once the cost exceeds the gain by more than an
//! allowance. Once the renderer has drawn directly (large batches shared over the
//! rasterizer's threads), the rate of such draws is known, and a frame also stops when its
//! whole time so far exceeds what drawing its work (the triangles drawn and removed) directly
//! would have cost, by more than the allowance: small tested batches rasterize slower than
//! shared ones, which is a cost of testing too.
//!
//! The allowance is a share of the frame's expected direct cost (the triangles the last frame
//! drew or removed, times the cost of a triangle), and never less than [`MIN_ALLOWANCE_TIME`].
//! Tests pay late in a frame (what is hidden is reached after its occluders are drawn), so the
//! allowance must cover the start of a frame; it adapts across frames: halved after a frame
//! that stopped (down to [`MIN_ALLOWANCE`]), doubled after one whose tests paid (up to
//! [`MAX_ALLOWANCE`]). On a view where nothing is hidden the renderer converges to testing a
//! few percent of a frame, then drawing directly in large batches as brute force does. Frames
//! do not change (stopping only draws more), only the time.
//!
//! Across frames, [`crate::direct::DirectFrames`] chooses whether a frame is culled at all,
//! from measured frame times, and hands back what a direct frame of the view is expected to
//! cost and the work it meets ([`Payoff::set_direct`]). The balance is then checked after
//! each batch too, and a frame plainly headed for four times a direct frame's time (all of
//! it spent while less than a quarter of the work was drawn or removed) is **abandoned**
//! ([`FramePayoff::abandoned`]): the renderer draws nothing more of it and the whole frame is
//! drawn directly instead (about two direct frames in all). Any other frame is finished as
//! begun, tests and all; the frame-level choice weighs it.
//!
//! Counters, registered by each renderer that uses it: `payoff_stopped` (1 when the frame
//! stopped testing), `payoff_untested` (the tests then skipped).

use std::time::{Duration, Instant};

/// Smallest share of a frame's expected direct cost a frame may lose finding out.
pub const MIN_ALLOWANCE: f64 = 1.0 / 64.0;
/// Largest share.
pub const MAX_ALLOWANCE: f64 = 0.25;
/// The least allowance, whatever the share: frames shorter than this never stop testing, so
/// small scenes keep their tests (and their counts) whatever the clock says.
pub const MIN_ALLOWANCE_TIME: Duration = Duration::from_millis(2);
/// Rasterization cost of a triangle before one was measured, ns (a typical software rate).
const PRIOR_NS_PER_TRIANGLE: f64 = 20.0;
/// Triangles a renderer gathers per batch once its frame stopped testing: large enough that the
/// rasterizer shares each batch over its threads, as brute force's draws are.
pub const DIRECT_BATCH: usize = 1 << 19;
/// Tests between two checks of the balance (a check reads the clock).
const CHECK_EVERY: u32 = 32;

/// What a renderer keeps across frames: the allowance, the measured cost of a triangle and
/// the triangles last seen in view.
#[derive(Clone, Debug)]
pub struct Payoff {
    enabled: bool,
    allowance: f64,
    ns_per_triangle: f64,
    /// Cost of a triangle in a batch shared over the rasterizer's threads, ns: what drawing
    /// directly costs; None until a frame drew such batches.
    direct_ns: Option<f64>,
    /// Triangles last frame drew or removed by tests: the work a direct frame would face.
    in_view: u64,
    /// Whether a direct frame was measured ([`crate::direct`]): a frame that stops is then
    /// abandoned.
    direct_known: bool,
    /// What a direct frame of the coming view is expected to cost, ns, and its work.
    direct_work: u64,
    /// What a direct frame of the coming view is expected to cost, ns.
    direct_frame_ns: f64,
    /// Whether the last frame's tests saved more than they cost ([`FramePayoff::paid`]).
    last_paid: bool,
    /// Whether the last frame was abandoned ([`FramePayoff::abandoned`]).
    last_abandoned: bool,
    /// Tests: every frame stops at its first check.
    #[cfg(test)]
    pub(crate) force_stop: bool,
}

impl Payoff {
    /// A fresh state. `enabled` false: frames never stop testing. `scene_triangles` is the
    /// first frame's estimate of the triangles in view (the whole scene).
    pub fn new(enabled: bool, scene_triangles: u64) -> Self {
        Self {
            enabled,
            allowance: MAX_ALLOWANCE,
            ns_per_triangle: PRIOR_NS_PER_TRIANGLE,
            direct_ns: None,
            in_view: scene_triangles,
            direct_known: false,
            direct_work: 0,
            direct_frame_ns: 0.0,
            last_paid: false,
            last_abandoned: false,
            #[cfg(test)]
            force_stop: false,
        }
    }

    /// Weighs the coming frames against drawing them directly: `known` once a direct frame was
    /// measured ([`crate::direct::DirectFrames`]), a direct frame of the view expected to take
    /// `frame_ns` for `work` triangles.
    pub fn set_direct(&mut self, known: bool, frame_ns: f64, work: u64) {
        self.direct_known = known;
        self.direct_frame_ns = frame_ns;
        self.direct_work = work;
    }

    /// Whether the last frame's tests saved more than they cost ([`FramePayoff::paid`] at its
    /// end).
    pub fn last_paid(&self) -> bool {
        self.last_paid
    }

    /// Whether the last frame was abandoned, to be redrawn directly
    /// ([`FramePayoff::abandoned`]).
    pub fn last_abandoned(&self) -> bool {
        self.last_abandoned
    }

    /// Starts weighing a frame that began at `start`.
    pub fn begin(&self, start: Instant) -> FramePayoff {
        FramePayoff {
            enabled: self.enabled,
            start,
            raster_time: Duration::ZERO,
            raster_triangles: 0,
            shared: (0, Duration::ZERO),
            saved_triangles: 0,
            last_ns_per_triangle: self.ns_per_triangle,
            direct_ns: self.direct_ns,
            abandon: self.direct_known,
            direct_frame_ns: self.direct_frame_ns,
            direct_work: self.direct_work,
            #[cfg(test)]
            force_stop: self.force_stop,
            allowance_triangles: self.allowance * self.in_view as f64,
            stopped: false,
            since_check: 0,
            untested: 0,
        }
    }

    /// Learns from a finished frame: the allowance, the cost of a triangle, the work in view.
    pub fn end(&mut self, f: &FramePayoff) {
        self.last_paid = f.paid(Instant::now());
        self.last_abandoned = f.abandoned();
        self.ns_per_triangle = f.ns_per_triangle();
        if f.shared.0 > 0 {
            let measured = f.shared.1.as_nanos() as f64 / f.shared.0 as f64;
            self.direct_ns = Some(self.direct_ns.map_or(measured, |d| 0.5 * d + 0.5 * measured));
        }
        self.in_view = f.raster_triangles + f.saved_triangles;
        if f.stopped {
            self.allowance = (self.allowance * 0.5).max(MIN_ALLOWANCE);
        } else if f.gain_ns() >= f.cost_ns(Instant::now()) {
            self.allowance = (self.allowance * 2.0).min(MAX_ALLOWANCE);
        }
    }
}

/// One frame's balance of test cost against gain ([module doc](self)).
#[derive(Clone, Debug)]
pub struct FramePayoff {
    enabled: bool,
    start: Instant,
    raster_time: Duration,
    raster_triangles: u64,
    /// Triangles and time of the batches shared over the rasterizer's threads.
    shared: (u64, Duration),
    saved_triangles: u64,
    last_ns_per_triangle: f64,
    direct_ns: Option<f64>,
    /// A stop abandons the frame (a measured direct frame redraws it, [`crate::direct`]).
    abandon: bool,
    /// What a direct frame is expected to cost, ns, and the work it meets (with `abandon`).
    direct_frame_ns: f64,
    direct_work: u64,
    #[cfg(test)]
    force_stop: bool,
    allowance_triangles: f64,
    stopped: bool,
    since_check: u32,
    untested: u64,
}

impl FramePayoff {
    /// Rasterizing `triangles` (submitted) took `time`: not a cost of the tests. `shared`:
    /// the batch was large enough for the rasterizer to share over its threads, as a direct
    /// draw is (its rate is then what drawing directly costs).
    pub fn rasterized(&mut self, triangles: u64, time: Duration, shared: bool) {
        self.raster_triangles += triangles;
        self.raster_time += time;
        if shared {
            self.shared.0 += triangles;
            self.shared.1 += time;
        }
        // A batch can take longer than many tests: the balance is weighed after each too, once
        // a frame that stops is abandoned (its drawing in pieces is then the cost to stop).
        if self.enabled && self.abandon && !self.stopped {
            self.check(Instant::now());
        }
    }

    /// A test removed `triangles` triangle instances.
    pub fn saved(&mut self, triangles: u64) {
        self.saved_triangles += triangles;
    }

    /// Whether to run the next test; false once the frame stopped testing. Checks the balance
    /// every few tests.
    pub fn test(&mut self) -> bool {
        if self.stopped {
            self.untested += 1;
            return false;
        }
        if !self.enabled {
            return true;
        }
        self.since_check += 1;
        if self.since_check >= CHECK_EVERY {
            self.since_check = 0;
            if self.check(Instant::now()) {
                self.untested += 1;
                return false;
            }
        }
        true
    }

    /// Weighs the frame so far; true (and stopped) once testing no longer pays.
    fn check(&mut self, now: Instant) -> bool {
        let allowance = (self.allowance_triangles * self.ns_per_triangle()).max(MIN_ALLOWANCE_TIME.as_nanos() as f64);
        // Once the direct rate is known (a frame drew directly), the whole frame so far is
        // weighed against drawing its work directly: small tested batches rasterize slower
        // than shared ones, a cost of testing too.
        let elapsed = now.saturating_duration_since(self.start).as_nanos() as f64;
        let direct_too_slow = self.direct_ns.is_some_and(|d| {
            let work = (self.raster_triangles + self.saved_triangles) as f64 * d;
            elapsed > work + allowance
        });
        self.stopped = if self.abandon {
            // Abandoning costs what was spent plus a whole direct frame: only for a frame
            // plainly headed for four times a direct frame's time (its time spent with less
            // than a quarter of its work done).
            let progress = (self.raster_triangles + self.saved_triangles) as f64 / self.direct_work.max(1) as f64;
            elapsed > self.direct_frame_ns.max(MIN_ALLOWANCE_TIME.as_nanos() as f64) && progress < 0.25
        } else {
            direct_too_slow || self.cost_ns(now) > self.gain_ns() + allowance
        };
        #[cfg(test)]
        {
            self.stopped |= self.force_stop;
        }
        self.stopped
    }

    /// `n` tests skipped without asking [`test`](Self::test) one by one (a renderer that
    /// decides for a batch of tests at once), counted in `payoff_untested`.
    pub fn skipped(&mut self, n: u64) {
        self.untested += n;
    }

    /// True unless, as of `now`, the frame's tests cost more than they saved by more than
    /// [`MIN_ALLOWANCE_TIME`] (so short frames always pay): for renderers whose costs come
    /// before their tests and decide per frame whether to cull at all.
    pub fn paid(&self, now: Instant) -> bool {
        self.cost_ns(now) <= self.gain_ns() + MIN_ALLOWANCE_TIME.as_nanos() as f64
    }

    /// True once the frame stopped testing.
    pub fn stopped(&self) -> bool {
        self.stopped
    }

    /// True once the frame stopped testing while a measured direct frame's rate was known
    /// ([`Payoff::set_direct`]): the renderer then draws nothing more of the frame and
    /// hands it to [`crate::direct::DirectFrames::redraw`], which draws it whole as `frustum`
    /// does (a stopped frame was slower than that by more than its allowance; finishing it
    /// its own way, in pieces, would be slower still).
    pub fn abandoned(&self) -> bool {
        self.stopped && self.abandon
    }

    /// The counters `payoff_stopped` and `payoff_untested`.
    pub fn counters(&self) -> [(&'static str, u64); 2] {
        [
            ("payoff_stopped", self.stopped as u64),
            ("payoff_untested", self.untested),
        ]
    }

    /// This frame's rasterization cost of a triangle, ns; the last frame's before its first
    /// batch.
    fn ns_per_triangle(&self) -> f64 {
        if self.raster_triangles == 0 {
            return self.last_ns_per_triangle;
        }
        self.raster_time.as_nanos() as f64 / self.raster_triangles as f64
    }

    fn cost_ns(&self, now: Instant) -> f64 {
        now.saturating_duration_since(self.start)
            .saturating_sub(self.raster_time)
            .as_nanos() as f64
    }

    fn gain_ns(&self) -> f64 {
        self.saved_triangles as f64 * self.ns_per_triangle()
    }
}

/// The counters of [`FramePayoff::counters`], for registries.
pub const COUNTERS: [&str; 2] = ["payoff_stopped", "payoff_untested"];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disabled_never_stops() {
        let p = Payoff::new(false, 1_000_000);
        let mut f = p.begin(Instant::now() - Duration::from_secs(10));
        assert!((0..1000).all(|_| f.test()));
        assert!(!f.stopped());
    }

    #[test]
    fn stops_when_tests_cost_more_than_they_save() {
        // A frame that began 50 ms ago, removed nothing and rasterized for 1 ms: 49 ms of
        // tests against an allowance of a quarter of 1,000 triangles at 1 µs.
        let mut p = Payoff::new(true, 1_000);
        let mut f = p.begin(Instant::now() - Duration::from_millis(50));
        f.rasterized(1_000, Duration::from_millis(1), false);
        let ran = (0..1000).take_while(|_| f.test()).count();
        assert_eq!(ran, CHECK_EVERY as usize - 1);
        assert!(f.stopped());
        assert!(!f.test());
        assert_eq!(f.counters(), [("payoff_stopped", 1), ("payoff_untested", 2)]);
        assert!(!f.paid(Instant::now()));
        p.end(&f);
        assert_eq!(p.allowance, MAX_ALLOWANCE * 0.5);
        assert_eq!(p.ns_per_triangle, 1_000.0);
        assert_eq!(p.in_view, 1_000);
    }

    #[test]
    fn keeps_testing_while_tests_pay() {
        let mut p = Payoff::new(true, 1_000);
        p.allowance = MIN_ALLOWANCE;
        let mut f = p.begin(Instant::now() - Duration::from_millis(1));
        // A million triangles removed at 20 ns (the prior): 20 ms of gain against about 1 ms
        // of cost.
        f.saved(1_000_000);
        assert!((0..10 * CHECK_EVERY).all(|_| f.test()));
        // Time spent rasterizing is not a cost of the tests.
        f.rasterized(1_000, Duration::from_micros(30), true);
        assert!((0..10 * CHECK_EVERY).all(|_| f.test()));
        assert!(f.paid(Instant::now()));
        p.end(&f);
        assert_eq!(p.allowance, 2.0 * MIN_ALLOWANCE);
        assert_eq!(p.ns_per_triangle, 30.0);
        assert_eq!(p.direct_ns, Some(30.0));
        assert_eq!(p.in_view, 1_001_000);
    }
}
