//! The render worker: one thread that renders the latest request, and one short-lived thread
//! per renderer that builds it the first time it is chosen.
//!
//! The window thread never waits on it: it replaces the pending request ([`Worker::submit`])
//! and is told of each finished frame through the callback given to [`Worker::start`]. A
//! request whose renderer is still being built is drawn with the renderer of the previous
//! frame (the overlay says so), unless it is `strict` (script screenshots), which waits.
//!
//! Every renderer is built watched by one [`FrameControl`]: the window reads the progress of
//! the frame in flight from it ([`Worker::in_flight`]), and [`Worker::supersede`] cancels that
//! frame once it has run [`CANCEL_AFTER`] while a request that shows something else waits. A
//! cancelled frame is never shown nor written ([`Event::Cancelled`]); the window keeps the
//! last complete one.

use std::collections::{HashMap, HashSet};
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use occult_core::{Camera, ItemId, Scene, View, NO_ITEM};
use occult_raster::{shade, Frame};
use occult_render::{AlgoSpec, Algorithm, FrameControl, FrameStats, RenderError, RenderOptions, Renderer};

use crate::output;

/// What the window shows of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// The shaded colors, as `occult render` writes them.
    Color,
    /// Depth, as `occult render --depth-out` writes it (near white, far dark).
    Depth,
    /// Item ids in false color (one color per triangle instance).
    Items,
    /// The colors, with the pixels whose item differs from `zbuffer`'s frame in magenta.
    Exactness,
}

impl Mode {
    /// Every mode, in the order `M` cycles through them.
    pub const ALL: [Mode; 4] = [Mode::Color, Mode::Depth, Mode::Items, Mode::Exactness];

    /// Its name, as the script and the overlay write it.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Color => "color",
            Mode::Depth => "depth",
            Mode::Items => "items",
            Mode::Exactness => "exactness",
        }
    }

    /// The mode called `name`.
    pub fn parse(name: &str) -> Option<Mode> {
        Mode::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The next mode in [`Mode::ALL`].
    pub fn next(self) -> Mode {
        let i = Mode::ALL.iter().position(|&m| m == self).unwrap_or(0);
        Mode::ALL[(i + 1) % Mode::ALL.len()]
    }
}

/// One frame to render.
#[derive(Clone, Debug)]
pub struct Request {
    /// Increases with every request; frames carry the id of the request they answer.
    pub id: u64,
    /// The camera.
    pub camera: Camera,
    /// Frame size, pixels.
    pub width: u32,
    /// Frame size, pixels.
    pub height: u32,
    /// The renderer and its settings.
    pub algo: AlgoSpec,
    /// What to show.
    pub mode: Mode,
    /// Write the frame's colors there as PNG (the pixels `occult render` writes).
    pub shot: Option<PathBuf>,
    /// Wait for `algo` (and for `zbuffer` in [`Mode::Exactness`]) to be built instead of
    /// drawing with the previous renderer.
    pub strict: bool,
}

/// A finished frame.
pub struct Shown {
    /// The request it answers.
    pub id: u64,
    /// The renderer that drew it (the previous one while the requested one is built).
    pub label: String,
    /// Pixels.
    pub width: u32,
    /// Pixels.
    pub height: u32,
    /// `0x00RRGGBB`, row-major, row 0 at the top.
    pub pixels: Vec<u32>,
    /// The mode the pixels show.
    pub mode: Mode,
    /// The renderer's statistics.
    pub stats: FrameStats,
    /// Wall time of the render call, ms.
    pub render_ms: f64,
    /// Wall time of the whole frame (render, visible set, shading, display mode), ms.
    pub frame_ms: f64,
    /// Exactly visible triangles (distinct items in the frame).
    pub triangles_visible: u64,
    /// In [`Mode::Exactness`], pixels whose item differs from `zbuffer`'s; `None` while
    /// `zbuffer` is being built or in other modes.
    pub differing_pixels: Option<u64>,
    /// The screenshot the request asked for: where it went, or why it failed.
    pub shot: Option<Result<PathBuf, String>>,
    /// When the worker finished it.
    pub finished: Instant,
}

/// How long a frame runs before a newer request that shows something else cancels it: a
/// shorter frame is let finish, so that flying (a new camera every 10 ms) keeps showing
/// frames; a longer one (seconds, `rzb` on 10^14 triangles) starts over with the new camera,
/// and is shown once the camera rests that long.
pub const CANCEL_AFTER: Duration = Duration::from_millis(200);

/// What a request shows: two requests alike in it draw the same frame.
#[derive(Clone, Debug, PartialEq)]
struct Shows {
    camera: Camera,
    size: (u32, u32),
    algo: String,
    mode: Mode,
}

impl Shows {
    fn of(request: &Request) -> Self {
        Self {
            camera: request.camera,
            size: (request.width, request.height),
            algo: request.algo.label(),
            mode: request.mode,
        }
    }
}

/// The frame being drawn.
struct InFlight {
    id: u64,
    shows: Shows,
    started: Instant,
    /// It writes a screenshot: never cancelled (the shot is of the state it was asked in).
    shot: bool,
}

/// What the worker tells the window.
pub enum Event {
    /// A frame is ready.
    Frame(Box<Shown>),
    /// A renderer is built and ready, after `ms` milliseconds.
    Built {
        /// Its label.
        label: String,
        /// Build time, ms.
        ms: f64,
    },
    /// The frame in flight was cancelled ([`Worker::supersede`]): nothing to show.
    Cancelled,
    /// A renderer could not be built, or a frame not rendered.
    Failed {
        /// The renderer's label.
        label: String,
        /// Why.
        error: String,
    },
}

type BuildResult = (String, Result<Box<dyn Renderer>, String>, f64);

#[derive(Default)]
struct State {
    request: Option<Request>,
    built: Vec<BuildResult>,
    quit: bool,
    in_flight: Option<InFlight>,
}

type Shared = Arc<(Mutex<State>, Condvar)>;

fn lock(shared: &Shared) -> MutexGuard<'_, State> {
    // A panic in the worker leaves the state as consistent as before it: keep going.
    shared.0.lock().unwrap_or_else(|e| e.into_inner())
}

/// The handle the window holds.
pub struct Worker {
    shared: Shared,
    control: FrameControl,
}

impl Worker {
    /// Starts the worker thread on `scene`; `notify` is called from worker threads with each
    /// event.
    pub fn start(scene: Arc<Scene>, notify: impl Fn(Event) + Send + Sync + 'static) -> Self {
        let shared: Shared = Arc::new((Mutex::new(State::default()), Condvar::new()));
        let inner = Arc::clone(&shared);
        let control = FrameControl::new();
        let options = RenderOptions {
            raster: occult_raster::RasterConfig {
                control: control.clone(),
                ..Default::default()
            },
            ..Default::default()
        };
        std::thread::Builder::new()
            .name("occult-view-render".into())
            .spawn(move || Runner::new(scene, inner, Arc::new(notify), options).run())
            .expect("the OS refused a thread for the renderer");
        Self { shared, control }
    }

    /// Replaces the pending request (a request not yet started is dropped), and cancels the
    /// frame in flight if it is due ([`Worker::supersede`]).
    pub fn submit(&self, request: Request) {
        let mut state = lock(&self.shared);
        state.request = Some(request);
        Self::supersede_locked(&state, &self.control);
        drop(state);
        self.shared.1.notify_all();
    }

    /// Cancels the frame in flight when it has run [`CANCEL_AFTER`] and a newer request that
    /// shows something else (camera, size, renderer, mode) waits; never a frame that writes a
    /// screenshot. The window calls it as it ticks, so that a slow frame is cancelled once it
    /// is due even when no new input comes. Returns whether it cancelled.
    pub fn supersede(&self) -> bool {
        Self::supersede_locked(&lock(&self.shared), &self.control)
    }

    // Under the lock: the worker starts a frame (and resets the control) under it too, so a
    // cancel never reaches the frame after the one meant.
    fn supersede_locked(state: &State, control: &FrameControl) -> bool {
        let (Some(flight), Some(request)) = (&state.in_flight, &state.request) else {
            return false;
        };
        let due = !flight.shot
            && request.id > flight.id
            && flight.started.elapsed() >= CANCEL_AFTER
            && Shows::of(request) != flight.shows;
        if due && !control.is_cancelled() {
            control.cancel();
        }
        due
    }

    /// The frame in flight: the request it answers, the part of it done (0 to 1, as the
    /// renderer reports it: see `occult_render`'s doc) and how long it has run.
    pub fn in_flight(&self) -> Option<(u64, f32, Duration)> {
        let state = lock(&self.shared);
        let flight = state.in_flight.as_ref()?;
        Some((flight.id, self.control.progress(), flight.started.elapsed()))
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        lock(&self.shared).quit = true;
        self.shared.1.notify_all();
    }
}

type Notify = Arc<dyn Fn(Event) + Send + Sync>;

/// The worker thread's state.
struct Runner {
    scene: Arc<Scene>,
    shared: Shared,
    notify: Notify,
    /// What every renderer is built with: the control the window cancels through.
    options: RenderOptions,
    renderers: HashMap<String, Box<dyn Renderer>>,
    building: HashSet<String>,
    failed: HashSet<String>,
    /// The last request drawn: its id, the renderer used, whether the exactness check ran.
    done: Option<(u64, String, bool)>,
    frame: Option<Frame>,
    reference: Option<Frame>,
    distinct: Distinct,
}

const REFERENCE: &str = "zbuffer";

impl Runner {
    fn new(scene: Arc<Scene>, shared: Shared, notify: Notify, options: RenderOptions) -> Self {
        Self {
            scene,
            shared,
            notify,
            options,
            renderers: HashMap::new(),
            building: HashSet::new(),
            failed: HashSet::new(),
            done: None,
            frame: None,
            reference: None,
            distinct: Distinct::default(),
        }
    }

    fn run(mut self) {
        while let Some((request, label)) = self.next() {
            self.draw(&request, &label);
            lock(&self.shared).in_flight = None;
        }
    }

    /// Waits for a request to draw; returns it with the label of the renderer to draw it
    /// with, or `None` on quit.
    fn next(&mut self) -> Option<(Request, String)> {
        let shared = Arc::clone(&self.shared);
        let mut state = lock(&shared);
        loop {
            if state.quit {
                return None;
            }
            let built: Vec<BuildResult> = state.built.drain(..).collect();
            for (label, result, ms) in built {
                self.building.remove(&label);
                match result {
                    Ok(renderer) => {
                        self.renderers.insert(label.clone(), renderer);
                        (self.notify)(Event::Built { label, ms });
                    }
                    Err(error) => {
                        self.failed.insert(label.clone());
                        (self.notify)(Event::Failed { label, error });
                    }
                }
            }
            if let Some(request) = state.request.clone() {
                if let Some(label) = self.choice(&request) {
                    // Under the lock, as the window cancels (`Worker::supersede_locked`).
                    self.options.raster.control.reset();
                    state.in_flight = Some(InFlight {
                        id: request.id,
                        shows: Shows::of(&request),
                        started: Instant::now(),
                        shot: request.shot.is_some(),
                    });
                    return Some((request, label));
                }
            }
            state = shared.1.wait(state).unwrap_or_else(|e| e.into_inner());
        }
    }

    /// The renderer to draw `request` with now, if it is to be drawn now; starts the builds
    /// it needs.
    fn choice(&mut self, request: &Request) -> Option<String> {
        let wanted = request.algo.label();
        let exact = request.mode == Mode::Exactness;
        self.ensure_built(&request.algo);
        if exact {
            self.ensure_built(&AlgoSpec::from(Algorithm::ZBUFFER));
        }
        let have = self.renderers.contains_key(&wanted);
        let have_reference = self.renderers.contains_key(REFERENCE);
        if request.strict && (!have || (exact && !have_reference)) {
            let hopeless = self.failed.contains(&wanted) || (exact && self.failed.contains(REFERENCE));
            if !hopeless {
                return None;
            }
        }
        let label = if have {
            wanted
        } else {
            let previous = self.done.as_ref().map(|d| d.1.clone());
            previous.filter(|l| self.renderers.contains_key(l))?
        };
        match &self.done {
            Some((id, used, checked)) if *id == request.id => {
                let better_renderer = *used != label;
                let better_check = exact && !checked && have_reference;
                (better_renderer || better_check).then_some(label)
            }
            _ => Some(label),
        }
    }

    /// Starts building `algo` unless it is built, being built or failed.
    fn ensure_built(&mut self, algo: &AlgoSpec) {
        let label = algo.label();
        if self.renderers.contains_key(&label) || self.building.contains(&label) || self.failed.contains(&label) {
            return;
        }
        self.building.insert(label.clone());
        let (scene, shared, algo) = (Arc::clone(&self.scene), Arc::clone(&self.shared), algo.clone());
        let options = self.options.clone();
        let spawned = std::thread::Builder::new()
            .name(format!("occult-view-build-{label}"))
            .spawn(move || {
                let t = Instant::now();
                let result = algo
                    .build(scene, &options)
                    .map_err(|e| format!("building {}: {e}", algo.label()));
                let ms = t.elapsed().as_secs_f64() * 1e3;
                lock(&shared).built.push((algo.label(), result, ms));
                shared.1.notify_all();
            });
        if let Err(e) = spawned {
            self.building.remove(&label);
            self.failed.insert(label.clone());
            (self.notify)(Event::Failed {
                label,
                error: format!("cannot start a thread to build it: {e}"),
            });
        }
    }

    fn draw(&mut self, request: &Request, label: &str) {
        match self.try_draw(request, label) {
            Ok(Some(shown)) => (self.notify)(Event::Frame(Box::new(shown))),
            // Not marked done: the newer request that cancelled it is drawn next.
            Ok(None) => (self.notify)(Event::Cancelled),
            Err(error) => {
                // Marked done, so that the same request is not retried in a loop.
                self.done = Some((request.id, label.to_string(), true));
                (self.notify)(Event::Failed {
                    label: label.to_string(),
                    error,
                });
            }
        }
    }

    /// The frame for `request` drawn with `label`; `None` when it was cancelled.
    fn try_draw(&mut self, request: &Request, label: &str) -> Result<Option<Shown>, String> {
        let start = Instant::now();
        let (width, height) = (request.width, request.height);
        let view = View::new(request.camera, width, height).map_err(|e| format!("view: {e}"))?;
        let mut frame = match self.frame.take() {
            Some(f) if f.width() == width && f.height() == height => f,
            _ => Frame::new(width, height).map_err(|e| e.to_string())?,
        };
        let renderer = self
            .renderers
            .get_mut(label)
            .ok_or_else(|| format!("{label} is not built"))?;
        let t = Instant::now();
        let stats = match renderer.render(&view, &mut frame) {
            Ok(stats) => stats,
            Err(RenderError::Cancelled) => {
                self.frame = Some(frame);
                return Ok(None);
            }
            Err(e) => return Err(format!("{label} failed: {e}")),
        };
        let render_ms = t.elapsed().as_secs_f64() * 1e3;
        let triangles_visible = self.distinct.count(frame.items(), self.scene.item_count());
        shade(&mut frame, &self.scene, &view);
        let shot = request.shot.as_ref().map(|p| {
            output::write_color_png(&frame, p)
                .map(|()| p.clone())
                .map_err(|e| format!("{e:#}"))
        });
        let mut differing_pixels = None;
        if request.mode == Mode::Exactness {
            match self.reference_diff(&view, &frame)? {
                Diff::Cancelled => {
                    self.frame = Some(frame);
                    return Ok(None);
                }
                Diff::Pixels(d) => differing_pixels = Some(d),
                Diff::Unbuilt => {}
            }
        }
        let pixels = match request.mode {
            Mode::Color => color_pixels(&frame),
            Mode::Depth => frame.depth_image().pixels().map(|p| gray(p.0[0])).collect(),
            Mode::Items => frame.items().iter().map(|&i| item_color(i)).collect(),
            Mode::Exactness => {
                let mut pixels = color_pixels(&frame);
                if let Some(reference) = self.reference.as_ref().filter(|_| differing_pixels.is_some()) {
                    for ((p, a), b) in pixels.iter_mut().zip(frame.items()).zip(reference.items()) {
                        if a != b {
                            *p = 0x00ff_00ff;
                        }
                    }
                }
                pixels
            }
        };
        self.done = Some((request.id, label.to_string(), differing_pixels.is_some()));
        let shown = Shown {
            id: request.id,
            label: label.to_string(),
            width,
            height,
            pixels,
            mode: request.mode,
            stats,
            render_ms,
            frame_ms: start.elapsed().as_secs_f64() * 1e3,
            triangles_visible,
            differing_pixels,
            shot,
            finished: Instant::now(),
        };
        self.frame = Some(frame);
        Ok(Some(shown))
    }

    /// Renders `view` with `zbuffer` into the reference frame and counts the pixels whose
    /// item differs from `frame`'s.
    fn reference_diff(&mut self, view: &View, frame: &Frame) -> Result<Diff, String> {
        let Some(zbuffer) = self.renderers.get_mut(REFERENCE) else {
            return Ok(Diff::Unbuilt);
        };
        let mut reference = match self.reference.take() {
            Some(f) if f.width() == frame.width() && f.height() == frame.height() => f,
            _ => Frame::new(frame.width(), frame.height()).map_err(|e| e.to_string())?,
        };
        match zbuffer.render(view, &mut reference) {
            Ok(_) => {}
            Err(RenderError::Cancelled) => {
                self.reference = Some(reference);
                return Ok(Diff::Cancelled);
            }
            Err(e) => return Err(format!("{REFERENCE} failed: {e}")),
        }
        let differing = frame
            .items()
            .iter()
            .zip(reference.items())
            .filter(|(a, b)| a != b)
            .count() as u64;
        self.reference = Some(reference);
        Ok(Diff::Pixels(differing))
    }
}

/// What [`Runner::reference_diff`] found.
enum Diff {
    /// Pixels whose item differs from `zbuffer`'s.
    Pixels(u64),
    /// `zbuffer` is being built.
    Unbuilt,
    /// The reference frame was cancelled.
    Cancelled,
}

/// Counts the distinct items of a frame (the exactly visible triangles) without sorting: a
/// bit per item of the scene where the scene has at most [`Distinct::MAX_BITS`] items, else
/// a sorted copy ([`Frame::visible_items`]'s way).
#[derive(Default)]
struct Distinct {
    bits: Vec<u64>,
    sorted: Vec<ItemId>,
}

impl Distinct {
    /// 2^27 items: a 16 MiB bit set at most.
    const MAX_BITS: u64 = 1 << 27;

    fn count(&mut self, items: &[ItemId], item_count: u64) -> u64 {
        if item_count <= Self::MAX_BITS {
            self.bits.resize(item_count.div_ceil(64) as usize, 0);
            let mut distinct = 0;
            for &i in items.iter().filter(|&&i| i < item_count) {
                let (word, bit) = ((i / 64) as usize, 1u64 << (i % 64));
                distinct += u64::from(self.bits[word] & bit == 0);
                self.bits[word] |= bit;
            }
            // Clear only the words set: the frame, not the scene, bounds the cost.
            for &i in items.iter().filter(|&&i| i < item_count) {
                self.bits[(i / 64) as usize] = 0;
            }
            distinct
        } else {
            self.sorted.clear();
            self.sorted.extend(items.iter().copied().filter(|&i| i != NO_ITEM));
            self.sorted.sort_unstable();
            self.sorted.dedup();
            self.sorted.len() as u64
        }
    }
}

fn color_pixels(frame: &Frame) -> Vec<u32> {
    frame
        .color()
        .iter()
        .map(|c| (u32::from(c[0]) << 16) | (u32::from(c[1]) << 8) | u32::from(c[2]))
        .collect()
}

fn gray(v: u8) -> u32 {
    let v = u32::from(v);
    (v << 16) | (v << 8) | v
}

/// A color per item (a hash of its id, kept away from black); black where nothing was drawn.
pub fn item_color(item: ItemId) -> u32 {
    if item == NO_ITEM {
        return 0;
    }
    // splitmix64's finalizer: neighbouring ids get unrelated colors.
    let mut z = item.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z as u32 & 0x00ff_ffff) | 0x0030_3030
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn modes_cycle_and_parse() {
        let mut m = Mode::Color;
        for _ in 0..Mode::ALL.len() {
            assert_eq!(Mode::parse(m.name()), Some(m));
            m = m.next();
        }
        assert_eq!(m, Mode::Color);
        assert_eq!(Mode::parse("colour"), None);
    }

    #[test]
    fn distinct_items_are_counted_both_ways() {
        let items = [3, NO_ITEM, 3, 70, 0, 70, 5];
        let mut d = Distinct::default();
        assert_eq!(d.count(&items, 100), 4);
        assert_eq!(d.count(&items, 100), 4, "the bits are cleared after a count");
        assert_eq!(d.count(&items, Distinct::MAX_BITS + 1), 4);
        assert_eq!(d.count(&[], 100), 0);
    }

    fn request(id: u64, eye_x: f32, algo: &str, shot: bool) -> Request {
        Request {
            id,
            camera: Camera::look_at(occult_core::Vec3::new(eye_x, 0.0, 5.0), occult_core::Vec3::ZERO),
            width: 64,
            height: 48,
            algo: AlgoSpec::parse(algo).expect("a valid spec"),
            mode: Mode::Color,
            shot: shot.then(|| PathBuf::from("shot.png")),
            strict: false,
        }
    }

    /// The state with `flying` in flight for `ran` and `waiting` requested.
    fn state(flying: &Request, ran: Duration, waiting: Request) -> State {
        State {
            request: Some(waiting),
            in_flight: Some(InFlight {
                id: flying.id,
                shows: Shows::of(flying),
                started: Instant::now()
                    .checked_sub(ran)
                    .expect("the clock reaches back a second"),
                shot: flying.shot.is_some(),
            }),
            ..State::default()
        }
    }

    #[test]
    fn only_a_long_frame_of_another_state_without_a_shot_is_cancelled() {
        let long = CANCEL_AFTER + Duration::from_millis(50);
        let flying = request(1, 0.0, "rzb", false);
        let cases = [
            (
                "another camera, long",
                state(&flying, long, request(2, 1.0, "rzb", false)),
                true,
            ),
            (
                "another renderer, long",
                state(&flying, long, request(2, 0.0, "hzb", false)),
                true,
            ),
            (
                "the same state again",
                state(&flying, long, request(2, 0.0, "rzb", false)),
                false,
            ),
            (
                "a short frame",
                state(&flying, Duration::ZERO, request(2, 1.0, "rzb", false)),
                false,
            ),
            (
                "the frame's own request",
                state(&flying, long, request(1, 0.0, "rzb", false)),
                false,
            ),
        ];
        for (what, state, due) in cases {
            let control = FrameControl::new();
            assert_eq!(Worker::supersede_locked(&state, &control), due, "{what}");
            assert_eq!(control.is_cancelled(), due, "{what}");
        }
        let shooting = request(1, 0.0, "rzb", true);
        let control = FrameControl::new();
        let s = state(&shooting, long, request(2, 1.0, "rzb", false));
        assert!(
            !Worker::supersede_locked(&s, &control),
            "a frame writing a screenshot finishes"
        );
        assert!(
            !Worker::supersede_locked(&State::default(), &control),
            "nothing in flight"
        );
        assert!(!control.is_cancelled());
    }

    #[test]
    fn item_colors_are_never_black_except_for_none() {
        assert_eq!(item_color(NO_ITEM), 0);
        assert!((0..1000).all(|i| item_color(i) != 0));
        assert_ne!(item_color(1), item_color(2));
    }
}
