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
//! from measured frame times, and hands over the work a direct frame of the view meets and,
//! once one was measured, what it is expected to cost ([`Payoff::set_direct`]; before that,
//! an estimate from the rasterization rates seen). The balance is then checked after each
//! batch too, and a frame that has spent a direct frame's time, whose rest at its pace so far
//! would take longer than another, is **given up** ([`FramePayoff::given_up`]): the renderer
//! stops testing and draws the rest directly, keeping what it drew (at most a direct frame's
//! time beyond what was spent; `lzb`, whose far scene is found by rays, draws the rest of its
//! near set and its far leaves). A renderer's first
//! frame, which has no last frame's visible set to draw first, is given up earlier: once its tests met a quarter of its work and removed
//! less than an eighth of what they met, when at its pace the whole frame would take
//! more than 1.25 estimated direct frames (the estimate is the frame's own rate shared over
//! the threads, so on two threads or more a frame drawn on one always is; drawn in small
//! tested batches on one thread, a first view culling cannot help took about two), or once
//! they met an eighth and removed less than a sixteenth at more than twice that pace
//! ([`HOPELESS_PACE`]). Once a
//! direct frame was measured, any other frame is finished as begun, tests and all, unless
//! given up; the frame-level choice weighs it.
//!
//! What a frame draws untested before its tests begin (`hzb`'s visible list,
//! [`FramePayoff::untested_first`], [`FramePayoff::tests_begin`]) is neither a cost nor a gain
//! of its tests: only the give-up rules weigh it.
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
/// A frame is given up when the rest of it, at its pace so far, would take this many times a
/// direct frame (see [`FramePayoff::given_up`]): at least a direct frame's time is spent by
/// then, and culling that pays often pays late in a frame (what is hidden is reached after its
/// occluders), hence the margin over 1 (set when a frame given up was drawn again whole;
/// finishing it directly costs only its rest). The early rule for
/// a renderer's first frame ([`FramePayoff::given_up`]) weighs the whole frame at its pace
/// against this many estimated direct frames, before one was spent.
pub const ABANDON_MARGIN: f64 = 1.25;
/// Share of its work a first frame's tests meet before the early rule may give it up
/// ([`FramePayoff::given_up`]): what its tests removed by then says what they can remove.
pub const EARLY_PROGRESS: f64 = 0.25;
/// Share of what a first frame's tests met that they must remove for the early rule to let it
/// go on.
pub const EARLY_REMOVED: f64 = 0.125;
/// The early rule also gives up a first frame at half [`EARLY_PROGRESS`] whose tests removed
/// less than half [`EARLY_REMOVED`] of what they met, at this many times its estimated direct
/// pace: a view that culling plainly cannot help (on the suite's `forest`, terrain, Armadillo
/// and lost-empire orbits, 0–7 % removed at 2–4× the pace by then; views whose culling pays had
/// removed 10 % or more, or kept within twice the pace) costs an eighth of its work at that
/// pace, not a quarter.
pub const HOPELESS_PACE: f64 = 2.0;
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
    /// What a measured direct frame of the coming view is expected to cost, ns
    /// ([`crate::direct`]): a frame then stops only when it is given up. `None`
    /// before one was measured.
    direct_frame_ns: Option<f64>,
    /// The coming view's work: the triangles a direct frame would submit (0: unknown).
    direct_work: u64,
    /// Threads a direct frame's draws are shared over (for the estimate before a measurement).
    direct_threads: usize,
    /// The last frame's cost and gain of its tests ([`Payoff::last_paid`],
    /// [`Payoff::paid_together`]).
    last_balance: Balance,
    /// Whether a frame ended yet ([`Payoff::end`]): the first knows nothing of the view.
    ended: bool,
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
            direct_frame_ns: None,
            direct_work: 0,
            direct_threads: 1,
            last_balance: Balance {
                cost_ns: 0.0,
                gain_ns: 0.0,
            },
            ended: false,
            #[cfg(test)]
            force_stop: false,
        }
    }

    /// Weighs the coming frames against drawing them directly ([`crate::direct::DirectFrames`]):
    /// a direct frame of the view meets `work` triangles, over `threads` threads, and is
    /// expected to take `frame_ns` once one was measured (`None` before: the frame then
    /// estimates it from its own rasterization rate, see [`FramePayoff::given_up`]).
    pub fn set_direct(&mut self, frame_ns: Option<f64>, work: u64, threads: usize) {
        self.direct_frame_ns = frame_ns;
        self.direct_work = work;
        self.direct_threads = threads.max(1);
    }

    /// Whether no frame ended yet ([`Payoff::end`]): the coming one is the renderer's first
    /// culled frame (a renderer ends only the frames it culls).
    pub fn first_frame(&self) -> bool {
        !self.ended
    }

    /// Whether the last frame's tests saved more than they cost ([`FramePayoff::paid`] at its
    /// end).
    pub fn last_paid(&self) -> bool {
        Self::paid_together([self])
    }

    /// Whether the last frames of `parts`, drawn side by side as one frame (strips of
    /// columns, workers), paid together: their tests' costs summed no more than their gains
    /// summed (both in thread time), with one [`MIN_ALLOWANCE_TIME`] a part, so that a frame
    /// whose every part paid by [`FramePayoff::paid`] pays together too. A part whose own
    /// tests did not pay (a strip of sky, where nothing is hidden) does not make a frame
    /// whose other parts removed most of the work one that lost (measured: `hzb` on
    /// `city:blocks=32` `street:16`, one strip of four stopped, and the direct frames measured
    /// after it took 145 and 181 ms against culled frames of 9-20).
    pub fn paid_together<'a>(parts: impl IntoIterator<Item = &'a Payoff>) -> bool {
        let allowance = MIN_ALLOWANCE_TIME.as_nanos() as f64;
        let (cost, gain) = parts.into_iter().fold((0.0, 0.0), |(c, g), p| {
            (c + p.last_balance.cost_ns, g + p.last_balance.gain_ns + allowance)
        });
        cost <= gain
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
            direct_frame_ns: self.direct_frame_ns,
            direct_work: self.direct_work,
            direct_threads: self.direct_threads,
            first: !self.ended,
            given_up: false,
            #[cfg(test)]
            force_stop: self.force_stop,
            allowance_triangles: self.allowance * self.in_view as f64,
            stopped: false,
            since_check: 0,
            untested: 0,
            base: (Duration::ZERO, Duration::ZERO, 0, 0),
            untested_first: false,
        }
    }

    /// Learns from a finished frame: the allowance, the cost of a triangle, the work in view.
    pub fn end(&mut self, f: &FramePayoff) {
        self.ended = true;
        self.last_balance = Balance {
            cost_ns: f.cost_ns(Instant::now()),
            gain_ns: f.gain_ns(),
        };
        self.ns_per_triangle = f.ns_per_triangle();
        if f.shared.0 > 0 {
            let measured = f.shared.1.as_nanos() as f64 / f.shared.0 as f64;
            self.direct_ns = Some(self.direct_ns.map_or(measured, |d| 0.5 * d + 0.5 * measured));
        }
        self.in_view = f.raster_triangles + f.saved_triangles;
        if f.stopped {
            self.allowance = (self.allowance * 0.5).max(MIN_ALLOWANCE);
        } else if self.last_balance.gain_ns >= self.last_balance.cost_ns {
            self.allowance = (self.allowance * 2.0).min(MAX_ALLOWANCE);
        }
    }
}

/// What a finished frame's tests cost and saved, ns of thread time ([`FramePayoff::paid`]).
#[derive(Clone, Copy, Debug)]
struct Balance {
    cost_ns: f64,
    gain_ns: f64,
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
    /// What a measured direct frame is expected to cost, ns: a frame then stops only when it
    /// is given up.
    direct_frame_ns: Option<f64>,
    /// The work a direct frame meets (0: unknown), and the threads it is shared over.
    direct_work: u64,
    direct_threads: usize,
    /// The renderer's first frame (the early rule, [`FramePayoff::given_up`]).
    first: bool,
    /// The frame was given up ([`FramePayoff::given_up`]).
    given_up: bool,
    #[cfg(test)]
    force_stop: bool,
    allowance_triangles: f64,
    stopped: bool,
    since_check: u32,
    untested: u64,
    /// What the frame had spent, drawn and removed when its tested part began
    /// ([`FramePayoff::tests_begin`]): time, rasterization time, triangles drawn or removed,
    /// triangles removed.
    base: (Duration, Duration, u64, u64),
    /// The frame draws untested first ([`FramePayoff::untested_first`]): until its tests
    /// begin, only the give-up rules may stop it.
    untested_first: bool,
}

impl FramePayoff {
    /// The frame draws something untested before its tests begin ([`FramePayoff::tests_begin`]):
    /// meanwhile it is not stopped for tests that do not pay (it makes none), only given up
    /// by the give-up rules.
    pub fn untested_first(&mut self) {
        self.untested_first = true;
    }

    /// The frame's tests begin now: what it drew before without tests (`hzb`'s visible list,
    /// drawn in large batches) is neither a cost nor a gain of testing. The balance and the
    /// comparison with a direct frame's rate weigh only what comes after (what was drawn
    /// stays drawn whatever the frame does next); the give-up rules still weighs the whole
    /// frame.
    pub fn tests_begin(&mut self, now: Instant) {
        self.base = (
            now.saturating_duration_since(self.start),
            self.raster_time,
            self.raster_triangles + self.saved_triangles,
            self.saved_triangles,
        );
        self.untested_first = false;
    }

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
        // a frame can be given up (its drawing in pieces is then the cost to stop).
        if self.enabled && self.direct_work > 0 && !self.stopped {
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
            let work = (self.raster_triangles + self.saved_triangles - self.base.2) as f64 * d;
            elapsed - self.base.0.as_nanos() as f64 > work + allowance
        });
        // Giving up costs what was spent plus the rest drawn directly: only once a direct frame's time is spent, and the rest
        // of the frame at its pace so far would take longer than a direct frame by a margin.
        let progress =
            ((self.raster_triangles + self.saved_triangles) as f64 / self.direct_work.max(1) as f64).min(1.0);
        let given_up = self.gives_up(elapsed, progress, true) || self.forced_to_give_up();
        self.given_up = given_up;
        self.stopped = given_up
            || (self.direct_frame_ns.is_none()
                && !self.untested_first
                && (direct_too_slow || self.cost_ns(now) > self.gain_ns() + allowance));
        #[cfg(test)]
        {
            self.stopped |= self.force_stop;
        }
        self.stopped
    }

    /// The rules of [`FramePayoff::given_up`] after `elapsed` ns, `progress` (0..=1)
    /// of the frame done; the early rule only when `early` (its pace is in triangles met, a
    /// progress of the same kind).
    fn gives_up(&self, elapsed: f64, progress: f64, early: bool) -> bool {
        let expected = self.direct_frame_ns.unwrap_or_else(|| self.estimated_direct_ns());
        let least = MIN_ALLOWANCE_TIME.as_nanos() as f64;
        self.direct_work > 0
            && ((elapsed > expected.max(least) && elapsed * (1.0 - progress) > ABANDON_MARGIN * expected * progress)
                || (early && self.gives_up_early(elapsed, progress, expected.max(least))))
    }

    /// The early rule, for the renderer's first frame (no visible list or cells of a last
    /// frame to draw first; giving up costs the rest of the frame at the direct rate): its tests met [`EARLY_PROGRESS`] of its work and removed less than
    /// [`EARLY_REMOVED`] of what they met, and the whole frame at its pace so far longer than
    /// [`ABANDON_MARGIN`] estimated direct frames (`expected` ns; estimated from the frame's
    /// own rate shared over the threads, so on two threads or more this always holds of a
    /// frame drawn on one, and on one thread it says the tests cost too much). A first view
    /// that culling cannot help (nothing hidden, drawn in small batches on one thread) then
    /// costs about 1.25 direct frames, not two; one whose tests remove much goes on, however
    /// slow its start. Later frames draw what was visible first, which their tests do not
    /// remove: the share would give up frames that pay (measured: `oqgrid` on `city`
    /// streets, 1.77× → 1.28× `zbuffer`). A frame plainly hopeless by half that progress is
    /// given up then ([`HOPELESS_PACE`]).
    fn gives_up_early(&self, elapsed: f64, progress: f64, expected: f64) -> bool {
        let met = (self.raster_triangles + self.saved_triangles - self.base.2) as f64;
        let removed = (self.saved_triangles - self.base.3) as f64;
        let by = |share: f64, removed_share: f64, pace: f64| {
            met >= share * self.direct_work as f64
                && removed < removed_share * met
                && elapsed > pace * expected * progress
        };
        self.first
            && self.direct_frame_ns.is_none()
            && !self.untested_first
            && elapsed > MIN_ALLOWANCE_TIME.as_nanos() as f64
            && (by(EARLY_PROGRESS, EARLY_REMOVED, ABANDON_MARGIN)
                || by(EARLY_PROGRESS / 2.0, EARLY_REMOVED / 2.0, HOPELESS_PACE))
    }

    /// Tests (`force_stop`): a frame with a direct frame measured is given up at its
    /// first check.
    fn forced_to_give_up(&self) -> bool {
        #[cfg(test)]
        return self.force_stop && self.direct_frame_ns.is_some();
        #[cfg(not(test))]
        false
    }

    /// For a renderer whose tests are not per triangle (rays): `progress` (0..=1) of the
    /// frame's tests is done; weighs giving up by the same rule as the triangle count does
    /// ([`FramePayoff::given_up`]), not the early rule (whose pace is in triangles met: at the
    /// first wave of rays, none of their gain is known), and returns it. Never gives up when
    /// payoff is off or the frame's work is unknown.
    pub fn progressed(&mut self, progress: f64) -> bool {
        if self.enabled && !self.given_up {
            let elapsed = self.start.elapsed().as_nanos() as f64;
            let given_up = self.gives_up(elapsed, progress.clamp(0.0, 1.0), false) || self.forced_to_give_up();
            self.given_up = given_up;
            self.stopped |= given_up;
        }
        self.given_up
    }

    /// The triangles a direct frame of this view meets (0: unknown), as armed by
    /// [`crate::direct::DirectFrames::arm`].
    pub fn work(&self) -> u64 {
        self.direct_work
    }

    /// A direct frame's time before one was measured, ns: its work at the rate of this
    /// renderer's batches shared over the threads, if it drew any, else at this frame's own
    /// rate shared over the threads (an optimistic guess: the sooner a frame is given up).
    fn estimated_direct_ns(&self) -> f64 {
        let rate = self
            .direct_ns
            .unwrap_or_else(|| self.ns_per_triangle() / self.direct_threads as f64);
        rate * self.direct_work as f64
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

    /// True once the frame was given up: it stopped testing ([`FramePayoff::stopped`]) and
    /// draws its rest directly. Given up once the frame has spent a direct frame's time and
    /// the rest of it, at its pace so far (the share of its work drawn or removed), would take
    /// more than [`ABANDON_MARGIN`] direct frames, or, for a renderer's first frame, by the
    /// early rule ([module doc](self)). The direct frame's time is the measured one
    /// ([`Payoff::set_direct`]); before one was measured, an estimate from the rasterization
    /// rates seen (so that a first frame that culling cannot help, with no list of what was
    /// visible yet, is not finished in small tested batches).
    pub fn given_up(&self) -> bool {
        self.given_up
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

    /// Time spent outside rasterization since the tests began.
    fn cost_ns(&self, now: Instant) -> f64 {
        let (spent, raster, ..) = self.base;
        now.saturating_duration_since(self.start)
            .saturating_sub(spent)
            .saturating_sub(self.raster_time.saturating_sub(raster))
            .as_nanos() as f64
    }

    /// What the tests removed since they began, at this frame's cost of a triangle.
    fn gain_ns(&self) -> f64 {
        (self.saved_triangles - self.base.3) as f64 * self.ns_per_triangle()
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

    /// Parts of one frame drawn side by side (strips of columns) pay together: a part whose
    /// tests lost alone does not make the frame lose when the others saved more.
    #[test]
    fn parts_drawn_side_by_side_pay_together() {
        // A part that began `ago_ms` ago, rasterized 1,000 triangles in 1 ms (1 µs each) and
        // removed `saved`.
        let part = |ago_ms: u64, saved: u64| {
            let mut p = Payoff::new(true, 1_000);
            let mut f = p.begin(Instant::now() - Duration::from_millis(ago_ms));
            f.rasterized(1_000, Duration::from_millis(1), false);
            f.saved(saved);
            p.end(&f);
            p
        };
        let sky = part(50, 0); // about 49 ms of tests, nothing removed
        let street = part(10, 1_000_000); // about 9 ms of tests, 1 s of drawing removed
        assert!(!sky.last_paid());
        assert!(street.last_paid());
        assert!(Payoff::paid_together([&sky, &street]));
        // About 58 ms of tests against 50 ms removed: the frame lost.
        let thin = part(10, 50_000);
        assert!(thin.last_paid());
        assert!(!Payoff::paid_together([&sky, &thin]));
        assert!(Payoff::paid_together([&street]));
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

    /// What a frame draws untested first (a visible list) neither stops it while drawn nor
    /// counts against its tests after.
    #[test]
    fn what_is_drawn_untested_first_is_not_a_cost_of_the_tests() {
        let p = Payoff::new(true, 1_000);
        // 50 ms ago, 1,000 triangles drawn in 1 ms: 49 ms outside rasterization.
        let mut f = p.begin(Instant::now() - Duration::from_millis(50));
        f.untested_first();
        f.rasterized(1_000, Duration::from_millis(1), false);
        f.saved(500); // a retest among the untested draws
        assert!(!f.check(Instant::now()), "not stopped while drawing untested");
        f.tests_begin(Instant::now());
        assert_eq!(f.gain_ns(), 0.0, "what was removed before is no gain of the tests");
        f.saved(10);
        assert_eq!(f.gain_ns(), 10.0 * f.ns_per_triangle());
        assert!(
            (0..10 * CHECK_EVERY).all(|_| f.test()),
            "the tests begin with a clean balance"
        );
        assert!(f.paid(Instant::now()));
        // Without it, the same frame stops at its first check.
        let mut f = p.begin(Instant::now() - Duration::from_millis(50));
        f.rasterized(1_000, Duration::from_millis(1), false);
        assert!(f.check(Instant::now()));
    }

    /// A frame that spent a direct frame's time, with a tenth of its work done, is given up:
    /// the direct frame measured, or before a measurement estimated from the frame's own rate
    /// shared over the threads; one nearly done stops testing only (before a measurement) or
    /// goes on.
    #[test]
    fn gives_up_a_frame_plainly_slower_than_drawing_it_directly() {
        let ago = |ms| Instant::now() - Duration::from_millis(ms);
        // 1,000 triangles drawn at 10 µs each: a direct frame of 10,000 on 2 threads, 50 ms.
        let frame = |p: &Payoff, started: Instant, saved: u64| {
            let mut f = p.begin(started);
            f.saved(saved);
            f.rasterized(1_000, Duration::from_millis(10), false);
            f
        };
        let mut p = Payoff::new(true, 10_000);
        p.set_direct(None, 10_000, 2);
        let f = frame(&p, ago(60), 0);
        assert!(f.given_up() && f.stopped(), "60 ms, a tenth of the work: estimated");
        let f = frame(&p, ago(25), 0);
        assert!(!f.given_up() && !f.stopped(), "within the estimate and the allowance");
        let f = frame(&p, ago(500), 8_000);
        assert!(!f.given_up() && f.stopped(), "nearly done: stops testing only");
        p.set_direct(Some(200e6), 10_000, 2);
        let f = frame(&p, ago(60), 0);
        assert!(!f.stopped(), "within the measured 200 ms");
        let f = frame(&p, ago(250), 0);
        assert!(f.given_up() && f.stopped());
        let f = frame(&p, ago(500), 8_000);
        assert!(!f.stopped(), "measured: a frame nearly done goes on");
        p.set_direct(None, 0, 2);
        let f = frame(&p, ago(60), 0);
        assert!(!f.given_up(), "no work known, nothing to give up for");
    }

    /// A renderer's first frame is given up once its tests
    /// met a quarter of its work and removed less than an eighth of what they met, and its
    /// pace says the whole would take longer than the margin, or met an eighth and removed
    /// less than a sixteenth at more than twice the pace; not one whose tests remove, nor
    /// one on pace (one thread), nor one still drawing untested, nor by its rays' progress, nor a
    /// later frame, nor once a direct frame was measured.
    #[test]
    fn gives_up_early_a_first_frame_whose_tests_remove_nothing() {
        let ago = |ms| Instant::now() - Duration::from_millis(ms);
        // Triangles drawn at 10 µs each: an estimated direct frame of 10,000 on 2 threads,
        // 50 ms.
        let frame = |p: &Payoff, started: Instant, drawn: u64, saved: u64| {
            let mut f = p.begin(started);
            f.saved(saved);
            f.rasterized(drawn, Duration::from_micros(10 * drawn), false);
            f
        };
        let mut p = Payoff::new(true, 10_000);
        p.set_direct(None, 10_000, 2);
        let f = frame(&p, ago(40), 3_000, 0);
        assert!(f.given_up() && f.stopped(), "40 ms, nothing removed");
        assert!(
            !frame(&p, ago(10), 2_000, 0).given_up(),
            "less than a quarter met, under twice the pace"
        );
        assert!(
            frame(&p, ago(30), 2_000, 0).given_up(),
            "an eighth met at three times the pace"
        );
        assert!(
            !frame(&p, ago(30), 2_000, 200).given_up(),
            "a tenth removed by an eighth"
        );
        assert!(!frame(&p, ago(30), 1_000, 0).given_up(), "less than an eighth met");
        assert!(!frame(&p, ago(30), 3_000, 500).given_up(), "a seventh removed");
        assert!(frame(&p, ago(40), 3_000, 400).given_up(), "less than an eighth removed");
        assert!(!frame(&p, ago(30), 3_000, 6_000).given_up(), "two thirds removed");
        // One thread: an estimated direct frame of 100 ms; 4,400 triangles met, the whole at
        // its pace is within 1.25 estimates until 55 ms, and the late rule waits for 100.
        let mut one = Payoff::new(true, 10_000);
        one.set_direct(None, 10_000, 1);
        assert!(!frame(&one, ago(41), 4_400, 0).given_up(), "on pace");
        assert!(frame(&one, ago(70), 4_400, 0).given_up(), "behind its pace");
        // Untested first: not given up early until its tests begin.
        let mut f = p.begin(ago(40));
        f.untested_first();
        f.rasterized(3_000, Duration::from_millis(30), false);
        assert!(!f.given_up(), "still drawing untested");
        f.tests_begin(Instant::now());
        f.rasterized(3_000, Duration::from_millis(30), false);
        assert!(f.given_up(), "its tests met a quarter and removed nothing");
        // Rays (`progressed`): the early rule does not weigh them, the triangle check does.
        let mut f = p.begin(ago(40));
        f.direct_work = 0;
        f.rasterized(3_000, Duration::from_millis(30), false);
        f.direct_work = 10_000;
        assert!(!f.progressed(0.0), "no ray's gain known yet");
        assert!(f.check(Instant::now()), "its tests met a quarter and removed nothing");
        let mut later = Payoff::new(true, 10_000);
        later.set_direct(None, 10_000, 2);
        later.end(&later.begin(Instant::now()));
        assert!(!frame(&later, ago(30), 3_000, 0).given_up(), "not the first frame");
        p.set_direct(Some(50e6), 10_000, 2);
        assert!(!frame(&p, ago(30), 3_000, 0).given_up(), "measured: the late rule only");
    }
}
