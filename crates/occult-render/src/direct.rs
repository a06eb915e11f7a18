//! Frames drawn directly: the frame-level half of the payoff guarantee ([`crate::payoff`]).
//!
//! Within a frame, [`FramePayoff`](crate::payoff::FramePayoff) stops testing once tests cost
//! more than they save. That bounds a frame's loss but cannot undo it, and on a view where
//! culling never pays (a single mesh in full view, open terrain) every frame would pay it
//! again. [`DirectFrames`] decides **per frame** whether a culling renderer culls at all or
//! draws the frame as `frustum` does (embedded [`Hierarchies`], drawn through the renderer's
//! own rasterizer: whole instances, `frustum`'s mesh BVHs, the same frame), from measured
//! costs:
//!
//! - a frame's **work** is the triangles `frustum` submits for its view (one walk of its
//!   hierarchies, counting only: cheap beside any frame); a direct frame's time is a fixed
//!   part (clear, walk) and its rasterization, a rate per triangle of work; the model is the
//!   least of each over the last [`DIRECT_KEPT`] direct frames (noise only adds time);
//! - a culled frame's time is compared with what the model predicts for its work, so that
//!   frames of different views compare (with the fill the rate misses: what the frame's draws
//!   shared over the threads took beyond twice the rate; a direct frame draws all it drew, and
//!   on a view of near facades a triangle costs several times the rate), and its gain (or loss) added to a decaying balance: a
//!   frame that loses while the balance is negative starts a **run** of direct frames when its
//!   tests did not pay by their own measure or the culled frame before lost too (the model
//!   knows triangles, not pixels: a near wall, few triangles and much to fill, is predicted
//!   cheap, so one loss of a frame whose tests paid is not trusted); a run is [`MIN_RUN`]
//!   frames the first time, twice as long after each probe that loses again, up to
//!   [`MAX_RUN`] (back to [`MIN_RUN`] after a probe that wins);
//! - the first direct frames ([`FIRST_MEASURED`] in a row: the first also pays the
//!   rasterizer's first large draws) are drawn after a culled frame whose tests did not pay,
//!   or after two in a row that did not plainly pay ([`DirectFrames::plainly`]: tests that
//!   paid, and at most a third of the work submitted or less than half of what the work would
//!   cost at the frame's own rasterization rate), unless that frame is small beside the
//!   culled frames before it (less than half their mean time); for `lzb` and `oqgrid`, after
//!   the renderer's first culled frame (of at least [`MIN_ALLOWANCE_TIME`]) when it did not
//!   plainly pay by time alone ([`DirectFrames::plainly_first`],
//!   [`DirectFrames::judging_first_by_time`]: its own rate shared over the threads, whatever
//!   share it submitted); or after the renderer's first culled
//!   frame when it took longer than its work at its own cost of a triangle shared over the
//!   threads (a view that culling cannot help then costs one culled frame, not two); a
//!   culled frame that wins by a thin margin (more than [`REMEASURE_SHARE`] of the predicted
//!   direct time) measures it again once the measurement is [`REMEASURE_AFTER`] frames old;
//!   a single measurement (it may be cold or interrupted) is taken again after
//!   [`REMEASURE_FIRST`] culled frames, unless they win by more than a cold measurement
//!   could make up (less than [`COLD_SHARE`] of its prediction);
//! - a culled frame shorter than [`MIN_ALLOWANCE_TIME`] never starts a run (small scenes keep
//!   their tests whatever the clock says);
//! - probes are **screened**: the last direct frame of a run has its final depth, and what a
//!   culled frame could remove at most is what lies behind it: the triangles under the boxes
//!   of `frustum`'s hierarchies hidden by that depth
//!   ([`Hierarchies::hidden_triangles`], Greene's box test through a pyramid of it). When
//!   drawing those directly costs less than culling cost the last culled frame (its time
//!   beyond a direct frame of the triangles it submitted; scaled down by the views' work when
//!   this view holds less), the probe cannot pay and the next
//!   run starts instead, doubled as after a losing probe (a screening is a walk of the
//!   hierarchies, its mesh hierarchies shared over the rasterizer's threads and, beyond 512
//!   of them, a sample descended, its estimate leaning high: a few percent of a frame; a
//!   losing probe costs up to two frames). Only with
//!   a culled frame at most [`SCREEN_AGE`] frames old, and by a direct frame of at least
//!   [`MIN_ALLOWANCE_TIME`] (a view of next to nothing says nothing of the next); before the first direct frame, a culled
//!   frame that did not plainly pay is screened the same way on its own depth, at its own
//!   cost of a triangle, and the direct frames are measured next when it cannot pay (not the
//!   first culled frame of a renderer judging it by time: it is measured next anyway).
//!
//! Renderers also hand the expected direct frame to their in-frame payoff, which then gives
//! up a frame plainly slower than drawing it directly (its rest is drawn directly)
//! ([`FramePayoff::given_up`](crate::payoff::FramePayoff::given_up)).
//! Frames do not change (`frustum` is exact), only the time. Counters: `payoff_direct` (1 for
//! a frame drawn directly), `payoff_screened` (1 for a frame whose screening skipped a probe
//! or, before the first measurement, a culled frame).

use std::sync::Arc;
use std::time::{Duration, Instant};

use occult_core::{Scene, View};
use occult_raster::{Frame, Rasterizer, ZPyramid};

use crate::frustum::{FrustumOptions, Hierarchies};
use crate::payoff::{Payoff, MIN_ALLOWANCE_TIME};
use crate::{FrameStats, Phase, Result};

/// Longest run of direct frames between two probes of culling.
pub const MAX_RUN: u32 = 64;
/// First run of direct frames after culling lost: a probe costs a culled frame that loses, so
/// runs are long (on a 24-frame path that culling loses, frames 0 and 10 are culled).
pub const MIN_RUN: u32 = 8;
/// A culled frame paying less than this share of the direct rate measures it again ...
pub const REMEASURE_SHARE: f64 = 0.8;
/// ... once the last measurement is this many frames old ...
pub const REMEASURE_AFTER: u32 = 16;
/// ... or this many, while the model holds a single measurement: a renderer's first direct
/// frame may still be cold (its rasterizer's first large draws: 34–38 ms against 22 for the
/// next ones on `city` `circle:32`), and one cold measurement made culled frames slower than
/// a warm direct frame look like wins for 16 frames.
pub const REMEASURE_FIRST: u32 = 4;
/// ... unless the culled frame took less than this share of the single measurement's
/// prediction: the coldest measurement seen was 3.3× a warm one (61–67 ms against 20–25 on
/// `city` `circle:32`), which cannot make a win that wide a loss, and on a street of
/// `city:blocks=32`, where a direct frame takes ten culled frames' time (145 and 181 ms
/// against 9–20), measuring it again costs more than a cold measurement could.
pub const COLD_SHARE: f64 = 0.25;
/// Direct frames whose measurements are kept (the model takes the least of each part).
pub const DIRECT_KEPT: usize = 4;
/// Direct frames drawn in a row for the first measurement: a renderer's first direct frame
/// also pays its rasterizer's first large draws (fresh buffers faulted in, several times the
/// frame's own cost on a large scene), which would make culled frames look good for long.
pub const FIRST_MEASURED: u32 = 1;
/// The counter of frames drawn directly.
pub const COUNTER: &str = "payoff_direct";
/// The counter of frames screened as unable to pay: probes skipped because the frame before
/// showed that culling could not pay ([`DirectFrames::render_if_due`]), culled frames before
/// the first measurement ([`DirectFrames::culled`]), `nbuffer`'s first culled frame drawn
/// again directly.
pub const SCREENED: &str = "payoff_screened";
/// A screening needs the test cost of a culled frame at most this many frames old (views
/// change: an old cost may not be this view's).
pub const SCREEN_AGE: u32 = 2 * MAX_RUN;

/// The frame-level choice between culling and drawing directly ([module doc](self)).
pub struct DirectFrames {
    frustum: Hierarchies,
    choice: Choice,
    /// The depth pyramid of the last direct frame of a run (screening), made at the frame's
    /// size when first needed.
    pyramid: Option<ZPyramid>,
    /// The threads a direct frame's draws are shared over (the renderer's rasterizer's).
    threads: usize,
    /// The rasterizer's thread pool, which screenings share their walk over (`None`: the
    /// caller's).
    pool: Option<Arc<rayon::ThreadPool>>,
    /// Workers that draw a culled frame at once, each on one thread (strips of columns,
    /// [`DirectFrames::culled_on`]); 1 when a culled frame is one walk.
    culled_workers: usize,
}

impl DirectFrames {
    /// `frustum`'s hierarchies of `scene` (its default options; built on `raster`'s threads)
    /// and a fresh choice.
    ///
    /// # Errors
    /// None with the default options; [`Hierarchies::build`]'s otherwise.
    pub fn new(scene: Arc<Scene>, raster: &Rasterizer) -> Result<Self> {
        Ok(Self {
            frustum: Hierarchies::build(scene, raster, &FrustumOptions::default())?,
            choice: Choice::default(),
            pyramid: None,
            threads: raster.thread_count().max(1),
            pool: raster.thread_pool(),
            culled_workers: 1,
        })
    }

    /// The same, for a renderer whose culled frames are drawn by `workers` workers at once,
    /// each on one thread ([`crate::columns`]): their statistics' rasterization time is the
    /// workers' together, so the frame's cost of a triangle in wall time, which the time of
    /// the frame is weighed against, is that over the workers. Every judgement of a culled
    /// frame by its own rate then holds its wall time to the same bar as a frame of one walk
    /// (whose wall time is its thread time): a first frame that culls in about a direct
    /// frame's time on all threads is not taken for one that plainly pays.
    pub fn culled_on(mut self, workers: usize) -> Self {
        self.culled_workers = workers.max(1);
        self
    }

    /// The same, judging the renderer's first culled frame (of at least
    /// [`MIN_ALLOWANCE_TIME`]) by time alone ([`DirectFrames::plainly_first`]): for renderers
    /// whose tests cost what the share of the work they submit does not show, `lzb`'s rays
    /// and `oqgrid`'s queries (a ray's traversal, a query's scan of its box's pixels, are not
    /// bounded per test as a pyramid lookup is). `hzb` and `clusters` keep the share: their
    /// tests are such lookups, and their first frame, without the visible list or first pass
    /// the next ones draw, is no measure of them; measured (perf log, sixteenth session), a
    /// direct frame after it put `clusters` on `plant circle:32` into runs of direct frames
    /// that its screenings, weighing that first frame's cost, never ended (2.6 → 1.0×).
    /// `oqgrid`'s next frames draw last frame's cells first too; on the suite's cases its
    /// first frames were either plain by time or lost to a direct frame (city32-orbit).
    pub fn judging_first_by_time(mut self) -> Self {
        self.choice.first_by_time = true;
        self
    }

    /// Whether the renderer's first culled frame is judged by time alone (tests).
    #[cfg(test)]
    pub(crate) fn judges_first_by_time(&self) -> bool {
        self.choice.first_by_time
    }

    /// [`crate::Renderer::prepare`]'s part: the screenings' depth pyramid for frames of
    /// `width × height`, and the private frames of `raster`'s sort-last draws, which its
    /// direct frames use.
    ///
    /// # Errors
    /// Allocation refused.
    pub fn prepare(&mut self, raster: &mut Rasterizer, width: u32, height: u32) -> Result<()> {
        crate::prepare_raster(raster, self.frustum.scene(), width, height);
        crate::sized_pyramid(&mut self.pyramid, width, height)?;
        Ok(())
    }

    /// Draws this frame directly when the choice says so (counting it in `payoff_direct` and
    /// measuring its rate); `None` when the frame is to be culled: its work is then counted
    /// (what [`DirectFrames::arm`] hands over).
    ///
    /// # Errors
    /// The frame or view errors of [`Hierarchies::render`].
    pub fn render_if_due(
        &mut self,
        raster: &mut Rasterizer,
        view: &View,
        frame: &mut Frame,
    ) -> Result<Option<FrameStats>> {
        if !self.choice.take_direct() {
            self.choice.last_work = self.frustum.triangles_in_view(view);
            return Ok(None);
        }
        let mut stats = self.render(raster, view, frame)?;
        stats.counters.add(COUNTER, 1);
        let raster_time = stats.phases.get(Phase::Raster);
        self.choice.direct(stats.total, raster_time, stats.triangles_submitted);
        if self.choice.direct_left == 0 && self.choice.screens(stats.total) {
            let t = Instant::now();
            let hidden = self.hidden_triangles(view, frame)?;
            if !self.choice.worth_probing(hidden, stats.triangles_submitted) {
                self.choice.start_run();
                stats.counters.add(SCREENED, 1);
            }
            stats.phases.add(Phase::Cull, t.elapsed());
            stats.total += t.elapsed();
        }
        Ok(Some(stats))
    }

    /// [`Hierarchies::hidden_triangles`] of what `frame` holds (a frame drawn, or the part of
    /// one drawn so far).
    pub(crate) fn hidden_triangles(&mut self, view: &View, frame: &Frame) -> Result<u64> {
        let fits = |p: &ZPyramid| p.width() == frame.width() && p.height() == frame.height();
        if !self.pyramid.as_ref().is_some_and(fits) {
            self.pyramid = Some(ZPyramid::new(frame.width(), frame.height())?);
        }
        let pyramid = self.pyramid.as_mut().expect("made above");
        Ok(self
            .frustum
            .hidden_triangles(view, frame, pyramid, self.pool.as_deref()))
    }

    /// Draws the frame directly, neither measured nor counted (for frames a renderer cannot
    /// cull, such as one without occluders).
    ///
    /// # Errors
    /// As [`DirectFrames::render_if_due`].
    pub fn render(&mut self, raster: &mut Rasterizer, view: &View, frame: &mut Frame) -> Result<FrameStats> {
        self.frustum.render(raster, view, frame)
    }

    /// Redraws a frame that a renderer judged unable to pay (`nbuffer`'s first, screened), as
    /// `frustum` does (the frame is cleared first), adding its counts and phases to the culled part's
    /// `stats` and counting it in `payoff_direct`. Before a direct frame was measured, this
    /// one is, and the next frame is drawn directly too (as the first measurement always is,
    /// [`FIRST_MEASURED`]).
    ///
    /// # Errors
    /// As [`DirectFrames::render_if_due`].
    pub fn redraw(
        &mut self,
        raster: &mut Rasterizer,
        view: &View,
        frame: &mut Frame,
        stats: &mut FrameStats,
    ) -> Result<()> {
        let s = self.render(raster, view, frame)?;
        if self.choice.model().is_none() {
            self.choice
                .direct(s.total, s.phases.get(Phase::Raster), s.triangles_submitted);
            // The rest of the first measurement's frames (none while it is one frame).
            self.choice.direct_left += FIRST_MEASURED.saturating_sub(1 + self.choice.direct_left);
        }
        stats.add_counts(&s);
        stats.phases.merge(&s.phases);
        stats.counters.add(COUNTER, 1);
        Ok(())
    }

    /// Learns from the culled frame of `view` that [`DirectFrames::render_if_due`] declined,
    /// drawn into `frame`, which took `total` (its statistics `stats`); `tests_paid`: its
    /// tests saved more than they cost
    /// ([`Payoff::last_paid`](crate::payoff::Payoff::last_paid)). True when the next frames
    /// are to be drawn directly. A screening that says so is counted in `stats`
    /// ([`SCREENED`]).
    ///
    /// Before a direct frame was measured, a culled frame that did not plainly pay is
    /// screened: when even removing every triangle hidden behind its final depth
    /// ([`Hierarchies::hidden_triangles`]) would save less than its culling cost, at its own
    /// rasterization cost of a triangle in wall time ([`DirectFrames::culled_on`]), the direct
    /// frames are measured next. Not the first
    /// culled frame of a renderer [judging it by time](DirectFrames::judging_first_by_time),
    /// whose not paying plainly is enough: a direct frame is measured next without the walk.
    ///
    /// # Errors
    /// [`crate::RenderError::Raster`] when the screening's pyramid cannot be allocated.
    pub fn culled(
        &mut self,
        view: &View,
        frame: &Frame,
        total: Duration,
        stats: &mut FrameStats,
        tests_paid: bool,
    ) -> Result<bool> {
        let work = self.choice.last_work;
        let submitted = stats.triangles_submitted;
        // A triangle's cost on one thread, and in the frame's wall time (less when several
        // workers drew at once).
        let raster_ns = stats.phases.get(Phase::Raster).as_nanos() as f64 / submitted.max(1) as f64;
        let wall_ns = raster_ns / self.culled_workers as f64;
        let first = self.choice.model().is_none();
        // The renderer's first culled frame: a direct frame is measured next unless it paid
        // plainly by time alone.
        // (One that submitted nothing has no rate: the share judges it.)
        let first_frame = self.choice.first_by_time && first && self.choice.unweighed.is_empty() && submitted > 0;
        let slower = submitted > 0 && self.choice.first_lost(total, wall_ns, self.threads);
        let plainly = !slower
            && if first_frame {
                Self::plainly_first(tests_paid, total, wall_ns / self.threads as f64, work)
            } else {
                Self::plainly(tests_paid, total, submitted, wall_ns, work)
            };
        // Culling pays only if drawing the hidden triangles costs more than what culling cost
        // this frame beyond drawing what it submitted (both at this frame's rate: a direct
        // frame's is lower, which only widens the loss). Not walked for the first culled
        // frame, measured next anyway when it did not plainly pay.
        let cannot_pay = first
            && !plainly
            && total >= MIN_ALLOWANCE_TIME
            && (slower
                || (!first_frame
                    && wall_ns * (self.hidden_triangles(view, frame)? + submitted) as f64 <= total.as_nanos() as f64));
        if cannot_pay {
            stats.counters.add(SCREENED, 1);
        }
        let drawn = Drawn {
            triangles: stats.triangles_shared,
            ns: stats.raster_shared.as_nanos() as f64,
        };
        self.choice.last_culled = Some((total, submitted, work, drawn));
        self.choice.last_culled_age = 0;
        self.choice.drawn = drawn;
        self.choice.culled(total, work, tests_paid, plainly, cannot_pay);
        Ok(self.choice.direct_left > 0)
    }

    /// Whether a culled frame that took `total` paid plainly, needing no direct frame to tell:
    /// its tests paid, and it submitted at most a third of the `work`, or took less than half
    /// of what the work would cost at its own rasterization cost of a triangle (`raster_ns`;
    /// a direct frame's triangles, whole meshes in large batches, cost less each, hence the
    /// margin).
    pub fn plainly(tests_paid: bool, total: Duration, submitted: u64, raster_ns: f64, work: u64) -> bool {
        tests_paid && (submitted.saturating_mul(3) <= work || (total.as_nanos() as f64) < 0.5 * raster_ns * work as f64)
    }

    /// Whether the renderer's first culled frame, which took `total`, paid plainly: its tests
    /// paid, and it took less than half of what the `work` would cost at its own cost of a
    /// triangle shared over the threads (`shared_ns`). Stricter than [`DirectFrames::plainly`]:
    /// time alone, not the share of the work submitted, since a renderer whose tests cost more
    /// than its drawing can submit a ninth of the work and still lose (`lzb` on
    /// `city:blocks=32` from outside: 3.4 M of 29.5 M triangles in 273 ms, against 150 ms
    /// drawn directly). Judging one frame so costs at most one direct frame, measured once; a
    /// street's later frames keep the share (their direct model, of triangles and not pixels,
    /// would misjudge them).
    pub fn plainly_first(tests_paid: bool, total: Duration, shared_ns: f64, work: u64) -> bool {
        tests_paid && (total.as_nanos() as f64) < 0.5 * shared_ns * work as f64
    }

    /// Hands the coming culled frame's expectations to its in-frame `payoff`: the frame's
    /// work (counted by [`DirectFrames::render_if_due`]), what a direct frame of it is expected
    /// to take once one was measured, and the `threads` a direct frame is shared over.
    pub fn arm(&self, payoff: &mut Payoff, threads: usize) {
        let work = self.choice.last_work;
        payoff.set_direct(self.choice.model().map(|m| m.predict(work)), work, threads);
    }

    /// What a direct frame of the coming culled frame's view is expected to take, ns, once one
    /// was measured (the prediction [`DirectFrames::arm`] hands over).
    pub fn expected_ns(&self) -> Option<f64> {
        self.choice.model().map(|m| m.predict(self.choice.last_work))
    }

    /// The triangles a direct frame of the coming culled frame's view meets (counted by
    /// [`DirectFrames::render_if_due`]).
    pub fn work(&self) -> u64 {
        self.choice.last_work
    }

    /// Bytes held (`frustum`'s hierarchies, the screening's pyramid).
    pub fn memory_bytes(&self) -> usize {
        self.frustum.memory_bytes() + self.pyramid.as_ref().map_or(0, ZPyramid::memory_bytes)
    }

    /// Makes the next `n` frames direct (tests of the renderers that embed one); `abandon`:
    /// with a direct rate known, so that frames that stop are given up.
    #[cfg(test)]
    pub(crate) fn force(&mut self, n: u32, abandon: bool) {
        self.choice.direct_left = n;
        if abandon {
            self.force_rate(1.0);
        }
    }

    /// Sets the measured direct rate (tests: frames that stop are then given up).
    #[cfg(test)]
    pub(crate) fn force_rate(&mut self, ns: f64) {
        self.choice.measured = vec![Model {
            fixed_ns: 0.0,
            rate_ns: ns,
        }];
    }
}

/// What a direct frame costs: a fixed part (clearing the frame, walking the hierarchies) and
/// a part per triangle of work (rasterizing).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Model {
    fixed_ns: f64,
    rate_ns: f64,
}

impl Model {
    /// The expected time of a direct frame of `work` triangles, ns.
    fn predict(&self, work: u64) -> f64 {
        self.fixed_ns + self.rate_ns * work as f64
    }

    /// The expected time of a direct frame of `work` triangles of a view whose culled frame
    /// drew what `drawn` says, ns: [`Model::predict`] and the fill the rate misses, what the
    /// culled frame's shared draws took beyond [`FILL_MARGIN`] times the rate for their
    /// triangles. A direct frame draws every triangle the culled one drew; on a view of near
    /// facades a triangle costs several times the rate (its pixels), which the rate alone
    /// misses. Within the margin, a shared draw's triangles may cost more than a direct
    /// frame's for other reasons (index lists transform a triangle's corners one by one).
    fn predict_after(&self, work: u64, drawn: Drawn) -> f64 {
        let fill = drawn.ns - FILL_MARGIN * self.rate_ns * drawn.triangles as f64;
        self.predict(work) + fill.max(0.0)
    }
}

/// A culled frame's draws shared over the rasterizer's threads cost at most this many times
/// the direct rate a triangle before the excess counts as fill the rate misses
/// ([`Model::predict_after`]).
const FILL_MARGIN: f64 = 2.0;

/// What a culled frame drew in draws the rasterizer shared over its threads, at a direct
/// frame's pace: their triangles and time, ns.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Drawn {
    triangles: u64,
    ns: f64,
}

/// The decision alone, on numbers: times and work.
#[derive(Clone, Debug, Default, PartialEq)]
struct Choice {
    /// The renderer's first culled frame is judged by time alone
    /// ([`DirectFrames::judging_first_by_time`]).
    first_by_time: bool,
    /// The last direct frames' models, newest last, at most [`DIRECT_KEPT`].
    measured: Vec<Model>,
    /// Culled frames (time, work, whether their tests paid, what they drew) not yet weighed:
    /// those before the first direct frame.
    unweighed: Vec<(Duration, u64, bool, Drawn)>,
    /// What the culled frame [`Choice::culled`] weighs drew (set just before; none: the model
    /// alone).
    drawn: Drawn,
    /// Culled frames in a row that did not plainly pay, before the first direct frame.
    unplain: u32,
    /// The balance of the recent culled frames: each one's gain (the predicted direct time of
    /// its work minus its time, ns) added to half the balance before; reset when a run
    /// starts. A frame of little work that loses a little does not outweigh frames before it
    /// that won much.
    balance: f64,
    /// Whether the last culled frame lost (slower than predicted for a direct frame).
    lost_last: bool,
    /// Direct frames left in the current run.
    direct_left: u32,
    /// Length of the next run (0: [`MIN_RUN`]).
    run: u32,
    /// Culled frames since the last direct one.
    since_direct: u32,
    /// The last frame's work.
    last_work: u64,
    /// The last culled frame's time, the triangles it submitted (its cost of culling is its
    /// time beyond a direct frame of those triangles), its work and what it drew; the direct
    /// frames since.
    last_culled: Option<(Duration, u64, u64, Drawn)>,
    last_culled_age: u32,
}

impl Choice {
    /// The direct frame model: the least fixed part and the least rate of the last direct
    /// frames (noise on a shared machine only ever adds time; one slow direct frame must not
    /// make culling look good). `None` before one was drawn.
    fn model(&self) -> Option<Model> {
        let fixed_ns = self.measured.iter().map(|m| m.fixed_ns).reduce(f64::min)?;
        let rate_ns = self.measured.iter().map(|m| m.rate_ns).reduce(f64::min)?;
        Some(Model { fixed_ns, rate_ns })
    }

    /// A culled frame's time over what a direct frame of its work is expected to take.
    fn ratio(&self, total: Duration, work: u64) -> Option<f64> {
        let m = self.model()?;
        Some(total.as_nanos() as f64 / m.predict(work).max(1.0))
    }

    /// Whether the renderer's first culled frame, which took `total` at `raster_ns` a
    /// triangle it drew, lost to a direct frame of its work: it took longer than that work at
    /// its own cost of a triangle shared over the `threads` (a direct frame's triangles, of
    /// whole meshes in large batches, cost less each). A direct frame is then measured next,
    /// without a screening. Only the first culled frame is judged so: later ones of little
    /// work (a street's) have a direct frame's fixed part (clearing, walking) to beat, which
    /// this estimate leaves out.
    fn first_lost(&self, total: Duration, raster_ns: f64, threads: usize) -> bool {
        self.model().is_none()
            && self.unweighed.is_empty()
            && total.as_nanos() as f64 > raster_ns / threads.max(1) as f64 * self.last_work as f64
    }

    /// Whether a run's last direct frame, which took `total`, screens the coming probe: a
    /// direct frame and a culled one were measured, the culled one recently ([`SCREEN_AGE`]),
    /// and this frame took at least [`MIN_ALLOWANCE_TIME`]. A shorter one is a view of next to
    /// nothing (a wall, the sky), where nothing is hidden, which says nothing of the views
    /// after it (measured: on `city` `street:32`, `nbuffer`'s views of 2 to 22 triangles
    /// started runs of direct frames where culled frames won); a culled frame that short never
    /// starts a run either.
    fn screens(&self, total: Duration) -> bool {
        total >= MIN_ALLOWANCE_TIME
            && self.model().is_some()
            && self.last_culled.is_some()
            && self.last_culled_age < SCREEN_AGE
    }

    /// Whether a probe may pay, on a view of `work` triangles of which at most `hidden` can be
    /// culled ([`Hierarchies::hidden_triangles`]): drawing the hidden ones directly must cost
    /// more than culling cost the last culled frame (its time beyond a direct frame of the
    /// triangles it submitted, with the fill the rate misses, [`Model::predict_after`]: its
    /// tests, and its smaller batches' slower drawing), scaled
    /// down to this view's work when it is less than that frame's (tests meet what is in view:
    /// on a street, a view of a facade holds a tenth of the view down the street before it,
    /// and weighed against the whole cost of that view's culling its probe was never drawn,
    /// measured). A bound in culling's favour: a culled frame removes less, drawing occluders
    /// first.
    fn worth_probing(&self, hidden: u64, work: u64) -> bool {
        if work == 0 {
            return true;
        }
        match (self.model(), self.last_culled) {
            (Some(m), Some((total, submitted, culled_work, drawn))) => {
                let share = (work as f64 / culled_work.max(1) as f64).min(1.0);
                let cost = (total.as_nanos() as f64 - m.predict_after(submitted, drawn)) * share;
                m.rate_ns * hidden.min(work) as f64 > cost
            }
            _ => true,
        }
    }

    /// True, and one direct frame fewer left, when this frame is to be drawn directly.
    fn take_direct(&mut self) -> bool {
        let due = self.direct_left > 0;
        self.direct_left = self.direct_left.saturating_sub(1);
        due
    }

    /// Starts a run of direct frames, twice as long as the last; the next probe alone weighs.
    fn start_run(&mut self) {
        self.balance = 0.0;
        let run = self.run.max(MIN_RUN);
        self.direct_left = run;
        self.run = (run * 2).min(MAX_RUN);
    }

    /// Weighs a culled frame of `work` triangles that took `total`; `cannot_pay`: before the
    /// first measurement, its own depth showed that culling cannot pay
    /// ([`DirectFrames::culled`]).
    fn culled(&mut self, total: Duration, work: u64, tests_paid: bool, paid_plainly: bool, cannot_pay: bool) {
        self.since_direct = self.since_direct.saturating_add(1);
        self.last_work = work;
        if total < MIN_ALLOWANCE_TIME {
            return;
        }
        if self.model().is_none() {
            // Measure the alternative, next frame, when this frame's tests did not pay, the
            // renderer's first culled frame or two frames in a row did not plainly pay; not for
            // a frame small beside the culled frames before it (a view of a wall: whatever it
            // loses is little, and weighed once a direct frame was measured).
            self.unplain = if paid_plainly { 0 } else { self.unplain + 1 };
            let n = self.unweighed.len() as f64;
            let mean = self.unweighed.iter().map(|u| u.0.as_secs_f64()).sum::<f64>() / n.max(1.0);
            let unplain = self.unplain >= 2 || (self.unplain == 1 && self.unweighed.is_empty() && self.first_by_time);
            if (cannot_pay || !tests_paid || unplain) && total.as_secs_f64() >= 0.5 * mean {
                self.direct_left = FIRST_MEASURED;
            }
            if self.unweighed.len() == DIRECT_KEPT {
                self.unweighed.remove(0);
            }
            self.unweighed.push((total, work, tests_paid, self.drawn));
            return;
        }
        if self.judge(total, work, tests_paid, self.drawn) {
            self.start_run();
            return;
        }
        if !self.lost_last {
            self.run = 0;
        }
        // A thin win against a direct frame measured long ago is measured again; against a
        // single measurement, soon, and after a loss that started no run too (every loss is
        // "thin": the measurement may be cold). A single measurement is taken again soon
        // unless the win is wider than a cold one could make (COLD_SHARE): a cold or
        // interrupted one (a first direct frame of 61-67 ms where warm ones take 20-25, `city`
        // `circle:32`) made culled frames of 33-46 ms wide wins, kept for 15-30 frames; it
        // costs one direct frame where culling wins.
        let ratio = self.ratio(total, work);
        let thin = ratio > Some(REMEASURE_SHARE) || (self.measured.len() == 1 && ratio > Some(COLD_SHARE));
        let after = match (self.measured.len(), self.lost_last) {
            (..=1, _) => REMEASURE_FIRST,
            (_, false) => REMEASURE_AFTER,
            (_, true) => u32::MAX,
        };
        if thin && self.since_direct >= after {
            self.direct_left = 1;
        }
    }

    /// Weighs a culled frame; true when a run of direct frames is due: the balance is negative
    /// and the frame lost, and either its tests did not pay (by their own measure) or the
    /// culled frame before lost too. A single loss of a frame whose tests paid is a view the
    /// model predicts badly (a near wall: few triangles, much to fill), not a reason to stop
    /// culling.
    fn judge(&mut self, total: Duration, work: u64, tests_paid: bool, drawn: Drawn) -> bool {
        let lost = self.weigh(total, work, drawn);
        let due = self.balance < 0.0 && lost && (!tests_paid || self.lost_last);
        self.lost_last = lost;
        due
    }

    /// Adds a culled frame's gain to the balance (against a direct frame of its view,
    /// [`Model::predict_after`] what it drew); true when it lost.
    fn weigh(&mut self, total: Duration, work: u64, drawn: Drawn) -> bool {
        let predicted = self.model().map_or(0.0, |m| m.predict_after(work, drawn));
        let gain = predicted - total.as_nanos() as f64;
        self.balance = 0.5 * self.balance + gain;
        gain < 0.0
    }

    fn direct(&mut self, total: Duration, raster: Duration, work: u64) {
        self.last_work = work;
        self.last_culled_age = self.last_culled_age.saturating_add(1);
        if self.measured.len() == DIRECT_KEPT {
            self.measured.remove(0);
        }
        self.measured.push(Model {
            fixed_ns: total.saturating_sub(raster).as_nanos() as f64,
            rate_ns: raster.as_nanos() as f64 / work.max(1) as f64,
        });
        self.since_direct = 0;
        // The culled frames before the first measurement, weighed now: straight into a run
        // when the last of them makes one due.
        let mut due = false;
        for (t, w, paid, drawn) in std::mem::take(&mut self.unweighed) {
            due = self.judge(t, w, paid, drawn);
        }
        if due {
            self.start_run();
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::{RenderOptions, Renderer};
    use occult_core::Vec3;
    use occult_raster::RasterConfig;

    const MS: Duration = Duration::from_millis(1);

    /// A choice whose model holds `n` measurements of a direct frame: `fixed_ns` and `rate_ns`
    /// a triangle.
    fn measured(fixed_ns: f64, rate_ns: f64, n: usize) -> Choice {
        Choice {
            measured: vec![Model { fixed_ns, rate_ns }; n],
            ..Choice::default()
        }
    }

    /// A row of cubes before more cubes on the ground, a view along the row, and the
    /// reference frame.
    pub(crate) fn scene_view_reference() -> (Arc<Scene>, View, Frame) {
        let at = (0..40).map(|i| Vec3::new((i % 8) as f32 * 1.5 - 6.0, 0.0, -((i / 8) as f32) * 2.0));
        let scene = crate::tests::cubes_on_ground([-9.0, 9.0, -20.0, 2.0], at);
        let (view, _) = crate::test_view(Vec3::new(0.5, 1.0, 4.0), Vec3::new(0.0, 0.0, -4.0), 96, 64);
        let reference = crate::tests::zbuffer_frame(&scene, &view);
        (scene, view, reference)
    }

    /// `hzb` of `scene` with its default options.
    fn default_hzb(scene: &Arc<Scene>) -> crate::hzb::Hzb {
        crate::hzb::Hzb::new(
            scene.clone(),
            &RenderOptions::default(),
            &crate::hzb::HzbOptions::default(),
        )
        .expect("hzb builds")
    }

    /// `oqgrid` of `scene` with its default options.
    fn default_oqgrid(scene: &Arc<Scene>) -> crate::oqgrid::OqGrid {
        let oq = crate::oqgrid::OqGridOptions::default();
        crate::oqgrid::OqGrid::with_options(scene.clone(), &RenderOptions::default(), &oq).expect("oqgrid builds")
    }

    /// Frames drawn directly, and frames whose culling is given up (finished untested), are
    /// the reference frames, counted as such; the renderers that embed
    /// [`DirectFrames`] each. `oqgrid` draws last frame's visible cells first, but not after
    /// direct frames (a list of a view since left).
    #[test]
    fn direct_and_given_up_frames_are_identical() {
        let (scene, view, reference) = scene_view_reference();
        let options = RenderOptions::default();
        let hzb = default_hzb(&scene);
        let oqgrid = default_oqgrid(&scene);
        // The paper's plane, so that rays are cast (giving up comes between waves of them).
        let lzb_options = crate::lzb::LzbOptions {
            plane: crate::lzb::Plane::Dynamic,
            ..Default::default()
        };
        let lzb = crate::lzb::Lzb::new(scene.clone(), &options, &lzb_options).expect("lzb builds");
        // Strips of columns on two threads.
        let two = RenderOptions {
            raster: RasterConfig {
                threads: 2,
                ..Default::default()
            },
            ..Default::default()
        };
        let columns = crate::oqgrid::OqGridOptions {
            parallel: crate::oqgrid::Parallel::Columns,
            ..Default::default()
        };
        let oqgrid_columns = crate::oqgrid::OqGrid::with_options(scene.clone(), &two, &columns).expect("oqgrid builds");
        let columns = crate::hzb::HzbOptions {
            distribution: crate::hzb::Distribution::Columns,
            ..Default::default()
        };
        let hzb_columns = crate::hzb::Hzb::new(scene.clone(), &two, &columns).expect("hzb builds");
        let mut renderers: Vec<(&str, Box<dyn ForceDirect>)> = vec![
            ("hzb", Box::new(hzb)),
            ("oqgrid", Box::new(oqgrid)),
            ("lzb", Box::new(lzb)),
            ("oqgrid:parallel=columns", Box::new(oqgrid_columns)),
            ("hzb:parallel=columns", Box::new(hzb_columns)),
        ];
        for (name, r) in &mut renderers {
            if name.starts_with("oqgrid") {
                // Two culled frames (forced: on a slow machine the first could send the second
                // to a direct frame): the second draws the first's visible cells first.
                for i in 0..2 {
                    r.force(0, false);
                    let mut f = Frame::new(96, 64).expect("a 96x64 frame");
                    let s = r.render(&view, &mut f).expect("the renderer renders the view");
                    assert!(f.same_visibility(&reference), "{name} culled frame {i}");
                    assert_eq!(s.counters.get(COUNTER), 0, "{name} culled frame {i}");
                    assert_eq!(s.counters.get("coherent_cells") > 0, i == 1, "{name} culled frame {i}");
                }
            }
            r.force(2, false);
            for i in 0..3 {
                if i == 2 {
                    // Culled, whatever a screening after the direct frames decided.
                    r.force(0, false);
                }
                let mut f = Frame::new(96, 64).expect("a 96x64 frame");
                let s = r.render(&view, &mut f).expect("the renderer renders the view");
                assert!(f.same_visibility(&reference), "{name} frame {i}");
                assert_eq!(s.counters.get(COUNTER), u64::from(i < 2), "{name} frame {i}");
                if i == 2 && name.starts_with("oqgrid") {
                    // Not the list of the view before the direct frames.
                    assert_eq!(s.counters.get("coherent_cells"), 0, "{name} frame {i}");
                }
            }
            r.force(0, true);
            let mut f = Frame::new(96, 64).expect("a 96x64 frame");
            let s = r.render(&view, &mut f).expect("the renderer renders the view");
            assert!(f.same_visibility(&reference), "{name} given up");
            // Finished untested, not drawn again.
            assert_eq!(s.counters.get(COUNTER), 0, "{name}: a frame given up is finished");
            // Once a strip of columns (each strip stops).
            let strips = s.counters.get(crate::columns::STRIPS).max(1);
            assert_eq!(s.counters.get("payoff_stopped"), strips, "{name}");
            // The frame after, from what the given-up frame left (its list, its state).
            let mut f = Frame::new(96, 64).expect("a 96x64 frame");
            r.render(&view, &mut f).expect("the renderer renders the view");
            assert!(f.same_visibility(&reference), "{name}: the frame after one given up");
        }
    }

    /// What the tests above set in a renderer that embeds [`DirectFrames`].
    pub(crate) trait ForceDirect: Renderer {
        /// Makes the next `n` frames direct; `abandon`: frames stop at their first balance
        /// check, with a direct rate known (so they are given up).
        fn force(&mut self, n: u32, abandon: bool);
        /// Its [`DirectFrames`].
        fn direct(&self) -> &DirectFrames;
    }

    /// `lzb` and `oqgrid` judge their first culled frame by time, `hzb` and `clusters` by the
    /// share; such a first frame that submitted a sliver of the work but took longer than
    /// half of it at its own rate measures a direct frame next, without the screening walk,
    /// where the share finds it plain.
    #[test]
    fn the_first_culled_frame_judged_by_time() {
        let (scene, view, _) = scene_view_reference();
        let options = RenderOptions::default();
        let lzb =
            crate::lzb::Lzb::new(scene.clone(), &options, &crate::lzb::LzbOptions::default()).expect("lzb builds");
        let oqgrid = default_oqgrid(&scene);
        let hzb = default_hzb(&scene);
        assert!(lzb.direct().judges_first_by_time());
        assert!(oqgrid.direct().judges_first_by_time());
        assert!(!hzb.direct().judges_first_by_time());
        let raster = occult_raster::Rasterizer::new(options.raster.clone()).expect("a rasterizer");
        for by_time in [false, true] {
            let mut d = DirectFrames::new(scene.clone(), &raster).expect("frustum hierarchies build");
            if by_time {
                d = d.judging_first_by_time();
            }
            let mut raster = occult_raster::Rasterizer::new(options.raster.clone()).expect("a rasterizer");
            let mut frame = Frame::new(96, 64).expect("a 96x64 frame");
            assert!(d
                .render_if_due(&mut raster, &view, &mut frame)
                .expect("counts the work")
                .is_none());
            let work = d.work();
            assert!(work > 100, "the view holds the cubes and the ground");
            // Ten triangles submitted, drawn in 10 ms: a frame of three quarters of the work
            // at that rate shared over the threads is not slower than it (`first_lost`), nor
            // plain by time (under half of it), but plain by the share.
            let mut stats = FrameStats {
                triangles_submitted: 10,
                ..FrameStats::default()
            };
            stats.phases.add(Phase::Raster, 10 * MS);
            let shared_ns = 1e6 / d.threads as f64;
            let total = Duration::from_nanos((0.75 * shared_ns * work as f64) as u64);
            let next_direct = d
                .culled(&view, &frame, total, &mut stats, true)
                .expect("no screening pyramid to fail");
            assert_eq!(next_direct, by_time, "judged by time: {by_time}");
            assert_eq!(stats.counters.get(SCREENED), 0, "no screening either way");
        }
    }

    /// Frames of a view where culling costs twice what drawing directly does and its tests do
    /// not pay: one measurement, then runs of 8, 16, 32 and 64 direct frames between probes.
    #[test]
    fn culling_that_loses_runs_direct_ever_longer() {
        let mut c = Choice::default();
        let mut ways = String::new();
        for _ in 0..120 {
            if c.take_direct() {
                ways.push('d');
                c.direct(10 * MS, 9 * MS, 1000);
            } else {
                ways.push('c');
                c.culled(20 * MS, 1000, false, false, false);
            }
        }
        let expected = format!(
            "cd{}c{}c{}c{}",
            "d".repeat(8),
            "d".repeat(16),
            "d".repeat(32),
            "d".repeat(64)
        );
        assert_eq!(ways, expected[..120]);
    }

    /// A culled frame is weighed against a direct frame that draws what it drew: what its
    /// shared draws cost beyond twice the rate is fill the rate misses, added to the model's
    /// prediction (on a view of near facades, its few triangles cost more than the rate says,
    /// and so would a direct frame's).
    #[test]
    fn a_direct_frame_draws_at_least_what_the_culled_frame_drew() {
        // 10 µs a triangle: a direct frame of 1000 is predicted 10 ms.
        let mut c = measured(0.0, 10_000.0, 2);
        assert!(c.weigh(12 * MS, 1000, Drawn::default()), "12 ms against 10: lost");
        // It drew 200 triangles in shared draws of 8 ms, 4 ms more than twice the rate: a
        // direct frame takes 14 ms.
        let filled = Drawn {
            triangles: 200,
            ns: 8e6,
        };
        assert!(!c.weigh(12 * MS, 1000, filled), "12 ms against 14: won");
        // Within twice the rate, the model's prediction stands.
        let quick = Drawn {
            triangles: 200,
            ns: 3.9e6,
        };
        assert!(c.weigh(12 * MS, 1000, quick), "12 ms against 10: lost");
        // The frames before the first measurement are weighed with what each drew.
        let mut first = Choice {
            drawn: filled,
            ..Choice::default()
        };
        first.culled(12 * MS, 1000, true, false, false);
        first.drawn = quick;
        first.culled(12 * MS, 1000, true, false, false);
        assert_eq!(first.unweighed.iter().map(|u| u.3).collect::<Vec<_>>(), [filled, quick]);
        let m = c.model().expect("measured");
        assert_eq!(m.predict_after(1000, Drawn::default()), m.predict(1000));
        assert_eq!(
            m.predict_after(
                1000,
                Drawn {
                    triangles: 100,
                    ns: 5e6
                }
            ),
            13e6
        );
    }

    /// A probe is screened out when drawing the triangles that could be hidden costs less
    /// than culling cost the last culled frame (scaled down to a view of less work); screening needs a recent culled frame and a
    /// direct frame of at least the least allowance; a
    /// first culled frame that cannot pay has the direct frames measured next.
    #[test]
    fn screening_weighs_hidden_triangles_against_the_cost_of_culling() {
        let mut c = measured(0.0, 10_000.0, 1);
        assert!(!c.screens(10 * MS), "no culled frame measured");
        // 14 ms for 1000 submitted triangles, 10 ms of drawing them directly: culling cost 4 ms.
        c.last_culled = Some((14 * MS, 1000, 1000, Drawn::default()));
        assert!(c.screens(10 * MS));
        assert!(!c.screens(MS), "a direct frame too short to say");
        assert!(!c.worth_probing(300, 1000), "at most 3 ms to save");
        assert!(c.worth_probing(500, 1000), "up to 5 ms to save");
        // A view of half that frame's work: half its cost of culling, 2 ms.
        assert!(c.worth_probing(250, 500), "2.5 ms to save");
        assert!(!c.worth_probing(150, 500), "1.5 ms to save");
        c.last_culled = Some((14 * MS, 1000, 200, Drawn::default()));
        assert!(!c.worth_probing(500, 300), "no more than the work is hidden");
        assert!(c.worth_probing(500, 2000), "the cost is not scaled up");
        assert!(c.worth_probing(0, 0), "a view of no work says nothing");
        for _ in 0..SCREEN_AGE {
            c.direct(10 * MS, 9 * MS, 1000);
        }
        assert!(!c.screens(10 * MS), "the culled frame is too old");
        let mut c = Choice::default();
        c.culled(20 * MS, 1000, true, false, true);
        assert!(c.take_direct(), "a first culled frame that cannot pay");
        let mut c = Choice::default();
        c.culled(20 * MS, 1000, true, true, false);
        c.culled(5 * MS, 1000, true, false, true);
        assert!(!c.take_direct(), "unless small beside the frames before");
    }

    /// The first culled frame loses when it took longer than its work at its own cost of a
    /// triangle shared over the threads; no later one is judged so, nor one after a direct
    /// frame was measured.
    #[test]
    fn a_first_culled_frame_slower_than_its_work_drawn_directly_lost() {
        let mut c = Choice {
            last_work: 1_000_000,
            ..Choice::default()
        };
        // A million triangles at 20 ns over 2 threads: 10 ms.
        assert!(c.first_lost(11 * MS, 20.0, 2));
        assert!(!c.first_lost(9 * MS, 20.0, 2));
        assert!(!c.first_lost(11 * MS, 20.0, 1), "one thread: 20 ms");
        c.culled(9 * MS, 1_000_000, true, true, false);
        assert!(!c.first_lost(100 * MS, 20.0, 2), "not the first culled frame");
        let mut c = measured(0.0, 1.0, 1);
        c.last_work = 1_000_000;
        assert!(!c.first_lost(100 * MS, 20.0, 2), "a direct frame was measured");
    }

    /// The hidden triangles of a view: some behind the front row, never one that a pixel of
    /// the frame shows, none behind an empty frame.
    #[test]
    fn hidden_triangles_are_not_shown() {
        let (scene, view, reference) = scene_view_reference();
        let raster = Rasterizer::new(RasterConfig::default()).expect("default rasterizer");
        let d = DirectFrames::new(scene.clone(), &raster).expect("frustum hierarchies build");
        let mut pyramid = ZPyramid::new(96, 64).expect("small pyramid");
        let hidden = d.frustum.hidden_triangles(&view, &reference, &mut pyramid, None);
        let shown: std::collections::HashSet<_> = reference
            .items()
            .iter()
            .copied()
            .filter(|&i| i != occult_core::NO_ITEM)
            .collect();
        let in_view = d.frustum.triangles_in_view(&view);
        assert!(hidden > 0, "the rows behind the first are hidden");
        assert!(
            hidden + shown.len() as u64 <= in_view,
            "{hidden} hidden + {} shown of {in_view} in view",
            shown.len()
        );
        let empty = Frame::new(96, 64).expect("small frame");
        assert_eq!(d.frustum.hidden_triangles(&view, &empty, &mut pyramid, None), 0);
        // With a hierarchy in every mesh (cubes of two triangles a leaf), the 41 mesh
        // occurrences' descents shared over threads: the same count, one thread or three.
        let fine = FrustumOptions {
            mesh_leaf_size: 2,
            ..FrustumOptions::default()
        };
        let fine = Hierarchies::build(scene, &raster, &fine).expect("frustum hierarchies build");
        let counts = crate::tests::on_threads(&[1, 3], |pool| {
            fine.hidden_triangles(&view, &reference, &mut pyramid, Some(pool))
        });
        // A visible cube's faces behind its front are hidden too: the meshes' part counted.
        assert!(counts[0] > hidden, "finer boxes hide more: {counts:?}, {hidden}");
        assert_eq!(counts[0], counts[1], "one thread or three");
    }

    /// Culling that wins keeps culling (after the first measurement's direct frames, and
    /// one more taken after [`REMEASURE_FIRST`] culled frames: the first may be cold),
    /// measuring again only when its margin is thin and the measurement old.
    #[test]
    fn culling_that_wins_keeps_culling() {
        let mut c = Choice::default();
        c.culled(20 * MS, 1000, false, false, false);
        for _ in 0..FIRST_MEASURED {
            assert!(c.take_direct());
            c.direct(40 * MS, 39 * MS, 1000);
        }
        for k in 1..=40 {
            c.culled(20 * MS, 1000, true, false, false);
            if c.take_direct() {
                assert_eq!(k, REMEASURE_FIRST, "the single measurement is taken again, once");
                c.direct(40 * MS, 39 * MS, 1000);
            } else {
                assert_ne!(k, REMEASURE_FIRST, "a wide margin remeasures no more");
            }
        }
        // A thin margin (36 of 40) remeasures at once (the measurement is 40 frames old),
        // then every 16th frame.
        let mut remeasured = 0;
        for _ in 0..40 {
            c.culled(36 * MS, 1000, true, false, false);
            if c.take_direct() {
                remeasured += 1;
                c.direct(40 * MS, 39 * MS, 1000);
            }
        }
        assert_eq!(remeasured, 3);
    }

    /// A single measurement that was cold (twice a warm direct frame) is taken again after
    /// [`REMEASURE_FIRST`] culled frames that win thinly against it, or lose without starting a
    /// run; the warm one then shows them as losses. With two measurements, thin wins wait
    /// [`REMEASURE_AFTER`] frames as before.
    #[test]
    fn a_single_cold_measurement_is_taken_again_soon() {
        let mut c = Choice::default();
        c.culled(40 * MS, 1000, false, false, false);
        assert!(c.take_direct());
        c.direct(40 * MS, 39 * MS, 1000); // cold: warm ones take 20 ms
        assert!(!c.take_direct(), "the culled frame before is weighed: a thin win");
        let mut culled = 0;
        while !c.take_direct() {
            c.culled(36 * MS, 1000, true, false, false);
            culled += 1;
            assert!(
                culled <= REMEASURE_FIRST,
                "remeasured after {REMEASURE_FIRST} culled frames"
            );
        }
        assert_eq!(culled, REMEASURE_FIRST);
        c.direct(20 * MS, 19 * MS, 1000);
        c.culled(36 * MS, 1000, true, false, false);
        c.culled(36 * MS, 1000, true, false, false);
        assert!(c.take_direct(), "two losses against the warm measurement start a run");
        // With two measurements, thin wins wait REMEASURE_AFTER frames as before.
        let mut c = measured(0.0, 40_000.0, 2);
        for _ in 0..REMEASURE_AFTER - 1 {
            c.culled(36 * MS, 1000, true, false, false);
            assert!(!c.take_direct());
        }
        c.culled(36 * MS, 1000, true, false, false);
        assert!(c.take_direct(), "the {REMEASURE_AFTER}th thin win remeasures");
        // One measurement, culled frames that lose by turns (tests paid: no run starts).
        let mut c = measured(0.0, 30_000.0, 1);
        for k in 0..REMEASURE_FIRST {
            assert!(!c.take_direct());
            let t = if k % 2 == 1 { 34 * MS } else { 20 * MS };
            c.culled(t, 1000, true, false, false);
        }
        assert!(c.take_direct(), "a loss that started no run remeasures too");
    }

    /// A single measurement is taken again after [`REMEASURE_FIRST`] culled frames, even
    /// against wide wins (it may have been cold: 64 ms where warm frames take 20); the least
    /// of two is trusted then. Not against a win wider than a cold measurement could make
    /// ([`COLD_SHARE`]).
    #[test]
    fn a_single_measurement_is_taken_again_unless_the_win_is_wider_than_cold() {
        let run = |measurements: usize, culled_ms: u32| {
            let mut c = measured(0.0, 64_000.0, measurements); // 64 ms for 1,000 triangles
            let mut culled = 0;
            while !c.take_direct() && culled < 40 {
                c.culled(culled_ms * MS, 1000, true, true, false);
                culled += 1;
            }
            culled
        };
        assert_eq!(run(1, 33), REMEASURE_FIRST, "a win of 0.52");
        assert_eq!(run(2, 33), 40, "two measurements: a wide win is trusted");
        assert_eq!(run(1, 15), 40, "a win of 0.23: no cold measurement makes it a loss");
    }

    /// A loss starts a run when its tests did not pay, or after another loss; a single loss
    /// of a frame whose tests paid does not.
    #[test]
    fn single_losses_of_paying_tests_are_not_trusted() {
        let mut c = measured(0.0, 10_000.0, 2);
        c.culled(30 * MS, 1000, true, false, false);
        assert!(!c.take_direct(), "one loss, tests paid");
        c.culled(9 * MS, 1000, true, false, false);
        c.culled(11 * MS, 1000, true, false, false);
        assert!(!c.take_direct(), "a win between");
        c.culled(11 * MS, 1000, true, false, false);
        assert!(c.take_direct(), "two losses in a row");
        let mut c = measured(0.0, 10_000.0, 2);
        c.culled(11 * MS, 1000, false, false, false);
        assert!(c.take_direct(), "a loss whose tests did not pay");
    }

    /// The first measurement: after tests that did not pay, or two frames in a row that did
    /// not plainly pay (the first culled frame alone, judged by time); never after a plain win
    /// or a small frame.
    #[test]
    fn when_direct_is_first_measured() {
        let mut c = Choice::default();
        c.culled(20 * MS, 1000, true, true, false);
        assert!(!c.take_direct(), "plainly paid");
        c.culled(20 * MS, 1000, true, false, false);
        assert!(!c.take_direct(), "once not plainly");
        c.culled(20 * MS, 1000, true, false, false);
        assert!(c.take_direct(), "twice not plainly");
        let mut c = Choice::default();
        c.culled(20 * MS, 1000, true, true, false);
        c.culled(5 * MS, 1000, false, false, false);
        assert!(!c.take_direct(), "small beside the frames before");
        c.culled(20 * MS, 1000, false, false, false);
        assert!(c.take_direct(), "tests that did not pay");
        // Judging the first culled frame by time: its not paying plainly is enough, and only
        // its own (a later frame keeps the two-in-a-row rule).
        let by_time = || Choice {
            first_by_time: true,
            ..Choice::default()
        };
        let mut c = by_time();
        c.culled(20 * MS, 1000, true, false, false);
        assert!(c.take_direct(), "the first culled frame, not plainly");
        let mut c = by_time();
        c.culled(20 * MS, 1000, true, true, false);
        c.culled(20 * MS, 1000, true, false, false);
        assert!(!c.take_direct(), "a later frame once not plainly");
        let mut c = Choice::default();
        c.culled(20 * MS, 1000, true, false, false);
        assert!(!c.take_direct(), "not judged by time: once is not enough");
        // By time alone: half the work at the rate shared over the threads, whatever the share
        // submitted; tests that paid.
        assert!(DirectFrames::plainly_first(true, 100 * MS, 1e6, 300));
        assert!(!DirectFrames::plainly_first(true, 150 * MS, 1e6, 300));
        assert!(!DirectFrames::plainly_first(false, 100 * MS, 1e6, 300));
        let mut c = Choice::default();
        c.culled(MIN_ALLOWANCE_TIME / 2, 1000, false, false, false);
        assert!(!c.take_direct(), "short frames keep their tests");
        assert!(c.unweighed.is_empty());
    }

    /// Frames are weighed against a direct frame's fixed part and rate; frames that won much
    /// outweigh a frame of little work that loses a little.
    #[test]
    fn the_model_and_the_balance() {
        let mut c = measured(8e6, 2000.0, 2);
        assert_eq!(c.model().map(|m| m.predict(1000)), Some(10e6));
        c.culled(3 * MS, 1, false, false, false);
        assert!(
            !c.take_direct(),
            "3 ms beats the 8 ms a direct frame needs whatever its work"
        );
        c.culled(5 * MS, 1000, false, false, false);
        c.culled(5 * MS, 1000, false, false, false);
        c.culled(11 * MS, 1, false, false, false);
        assert!(!c.take_direct(), "3 ms lost after 2 × 5 ms won");
        c.culled(11 * MS, 1, false, false, false);
        assert!(c.take_direct(), "lost again");
        // Submitted a third of the work, or took less than half of the work at its own rate.
        assert!(DirectFrames::plainly(true, 100 * MS, 100, 1.0, 300));
        assert!(!DirectFrames::plainly(true, 100 * MS, 101, 1.0, 300));
        assert!(!DirectFrames::plainly(false, 100 * MS, 1, 1.0, 300));
        assert!(DirectFrames::plainly(true, 100 * MS, 200, 1e6, 300));
        assert!(!DirectFrames::plainly(true, 200 * MS, 200, 1e6, 300));
    }
}
