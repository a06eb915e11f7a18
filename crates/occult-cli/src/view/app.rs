//! The window thread: input, camera, the overlays, and the script that may drive them.

use std::collections::HashSet;
use std::num::NonZeroU32;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use occult_core::Camera;
use occult_render::AlgoSpec;
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::PhysicalKey;
use winit::window::{Window, WindowId};

use super::fly::Fly;
use super::keys::{Action, Direction, HELP};
use super::overlay::Text;
use super::script::{Command, Script};
use super::worker::{Event, Mode, Request, Shown, Worker};
use crate::args::Size;
use crate::output;
use crate::scene::LoadedScene;

/// What the window starts with.
pub struct Setup {
    /// The scene.
    pub scene: LoadedScene,
    /// The first camera (R comes back to it).
    pub start: Camera,
    /// The path N, B and P go through.
    pub path: Vec<Camera>,
    /// The renderers keys 1-9 and Tab choose from; the first is shown first.
    pub algos: Vec<AlgoSpec>,
    /// The first frame size.
    pub size: Size,
    /// The script to run, if any.
    pub script: Option<Script>,
    /// Where C writes the recorded path.
    pub record_to: Option<PathBuf>,
}

/// Turning speed of held arrow keys, degrees per second.
const LOOK_DEG_PER_S: f32 = 90.0;
/// Mouse look, degrees per pixel.
const MOUSE_DEG_PER_PX: f32 = 0.2;
/// Orbit speed, degrees per second.
const ORBIT_DEG_PER_S: f32 = 20.0;
/// How often held keys move the camera (and the spinner turns).
const TICK: Duration = Duration::from_millis(10);
/// A frame in flight this long gets a progress bar (a shorter one would only flicker).
const PROGRESS_AFTER: Duration = Duration::from_millis(100);
/// The progress bar's height, pixels.
const PROGRESS_BAR_ROWS: usize = 4;
/// A scripted key press of a held key acts for this long.
const SCRIPT_PRESS_S: f32 = 1.0 / 30.0;
/// The longest a script waits for one frame (a renderer's build included).
const SCRIPT_TIMEOUT: Duration = Duration::from_secs(600);
const SPINNER: [char; 4] = ['|', '/', '-', '\\'];

/// Runs the window until it is closed or its script ends.
///
/// # Errors
/// No display; a script that fails (a build, a write, a timeout).
pub fn run(setup: Setup) -> Result<()> {
    let event_loop = EventLoop::<Event>::with_user_event()
        .build()
        .map_err(super::no_display)?;
    let proxy = Mutex::new(event_loop.create_proxy());
    let worker = Worker::start(Arc::clone(&setup.scene.scene), move |event| {
        // The window may be gone at exit: nothing left to tell.
        let _ = proxy.lock().unwrap_or_else(|e| e.into_inner()).send_event(event);
    });
    let mut app = App::new(setup, worker)?;
    event_loop.run_app(&mut app).context("the window's event loop")?;
    app.finish()
}

/// What a script waits for.
enum Wait {
    /// A frame of the current state.
    Frame,
    /// A frame of the current state under way (progress reported), or shown.
    Progress,
    /// A frame holding the screenshot asked for.
    Shot,
    /// The window as shown, once a frame of the current state is in it.
    Capture(PathBuf),
    /// The statistics of a frame of the current state.
    Stats(PathBuf),
    /// A moment.
    Until(Instant),
    /// Frames shown while flying.
    Fly {
        /// Frames still to show.
        until_frame: u64,
        /// When the flight began, and the frames shown then.
        start: Instant,
        frames_at_start: u64,
        render_ms: Vec<f64>,
    },
}

/// A script being run.
struct Run {
    commands: Vec<(usize, Command)>,
    next: usize,
    wait: Option<(Wait, Instant, usize)>,
}

struct App {
    scene: LoadedScene,
    start: Camera,
    path: Vec<Camera>,
    path_index: usize,
    algos: Vec<AlgoSpec>,
    algo: AlgoSpec,
    mode: Mode,
    size: Size,
    fly: Fly,
    worker: Worker,
    window: Option<Arc<Window>>,
    surface: Option<softbuffer::Surface<Arc<Window>, Arc<Window>>>,
    text: Text,
    composed: Vec<u32>,
    composed_size: (u32, u32),
    held: HashSet<Action>,
    shift: bool,
    buttons_down: u32,
    cursor: Option<(f64, f64)>,
    orbit: bool,
    playing: bool,
    show_help: bool,
    show_stats: bool,
    next_id: u64,
    last: Option<Box<Shown>>,
    frames_shown: u64,
    /// Frames cancelled by a newer state before they were complete (never shown).
    frames_cancelled: u64,
    frame_times: Vec<Instant>,
    pending_shot: Option<PathBuf>,
    shot_count: u32,
    recording: Option<Vec<Camera>>,
    record_to: Option<PathBuf>,
    building: Option<(String, Instant)>,
    /// The renderers the worker reported built.
    built: HashSet<String>,
    message: Option<(String, Instant)>,
    /// Inputs not yet reflected by a frame: request id, when, frames shown since.
    pending_inputs: Vec<(u64, Instant, u32)>,
    /// Latency of each input: frames finished after it until the first that reflects it
    /// (that one included), and milliseconds until the window has that frame.
    latencies: Vec<(u32, f64)>,
    flights: Vec<String>,
    script: Option<Run>,
    last_tick: Instant,
    error: Option<anyhow::Error>,
}

impl App {
    fn new(setup: Setup, worker: Worker) -> Result<Self> {
        let fly = Fly::new(setup.start, &setup.scene.scene.bounds());
        let algo = setup.algos.first().cloned().context("no renderer to show")?;
        Ok(Self {
            start: setup.start,
            path: setup.path,
            path_index: 0,
            algos: setup.algos,
            algo,
            mode: Mode::Color,
            size: setup.size,
            fly,
            worker,
            window: None,
            surface: None,
            text: Text::new(15.0)?,
            composed: Vec::new(),
            composed_size: (0, 0),
            held: HashSet::new(),
            shift: false,
            buttons_down: 0,
            cursor: None,
            orbit: false,
            playing: false,
            show_help: false,
            show_stats: true,
            next_id: 0,
            last: None,
            frames_shown: 0,
            frames_cancelled: 0,
            frame_times: Vec::new(),
            pending_shot: None,
            shot_count: 0,
            recording: None,
            record_to: setup.record_to,
            building: None,
            built: HashSet::new(),
            message: None,
            pending_inputs: Vec::new(),
            latencies: Vec::new(),
            flights: Vec::new(),
            script: setup.script.map(|s| Run {
                commands: s.commands,
                next: 0,
                wait: None,
            }),
            last_tick: Instant::now(),
            error: None,
            scene: setup.scene,
        })
    }

    /// After the window closed: the script's error, or what it measured.
    fn finish(self) -> Result<()> {
        if let Some(e) = self.error {
            return Err(e);
        }
        if self.script.is_some() {
            say!("{}", latency_line(&self.latencies, self.frames_shown));
            say!("frames cancelled: {}", self.frames_cancelled);
            for line in &self.flights {
                say!("{line}");
            }
        }
        Ok(())
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: anyhow::Error) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        event_loop.exit();
    }

    /// Sends the current state to the worker; `input` when a person's (or the script's)
    /// input caused it, for the latency count.
    fn submit(&mut self, input: bool) {
        self.next_id += 1;
        if input && self.pending_inputs.len() < 10_000 {
            self.pending_inputs.push((self.next_id, Instant::now(), 0));
        }
        if let Some(cameras) = &mut self.recording {
            if cameras.last() != Some(&self.fly.camera) {
                cameras.push(self.fly.camera);
            }
        }
        let strict = self.script.is_some();
        if !self.algo_known() {
            self.building = Some((self.algo.label(), Instant::now()));
        }
        self.worker.submit(Request {
            id: self.next_id,
            camera: self.fly.camera,
            width: self.size.width,
            height: self.size.height,
            algo: self.algo.clone(),
            mode: self.mode,
            shot: self.pending_shot.clone(),
            strict: strict && self.pending_shot.is_some(),
        });
        if let Some(w) = &self.window {
            w.request_redraw();
        }
    }

    fn algo_known(&self) -> bool {
        self.built.contains(&self.algo.label()) || self.last.as_ref().is_some_and(|f| f.label == self.algo.label())
    }

    fn set_camera(&mut self, camera: Camera) {
        self.fly.camera = camera;
        self.submit(true);
    }

    fn choose(&mut self, algo: AlgoSpec) {
        if !self.algos.iter().any(|a| a.label() == algo.label()) {
            self.algos.push(algo.clone());
        }
        self.algo = algo;
        self.submit(true);
    }

    fn algo_index(&self) -> usize {
        self.algos
            .iter()
            .position(|a| a.label() == self.algo.label())
            .unwrap_or(0)
    }

    /// A key pressed (`pressed`) or released, from the keyboard or the script.
    fn act(&mut self, event_loop: &ActiveEventLoop, action: Action, pressed: bool) {
        if action.is_held() {
            if pressed {
                self.held.insert(action);
            } else {
                self.held.remove(&action);
            }
            return;
        }
        if !pressed {
            return;
        }
        match action {
            Action::Fly(_) | Action::Look(_) => {}
            Action::Speed(s) => {
                self.fly.scale_speed(f32::from(s));
                self.say(format!("speed {:.3} units/s", self.fly.speed));
            }
            Action::Renderer(i) => {
                if let Some(a) = self.algos.get(i).cloned() {
                    self.choose(a);
                }
            }
            Action::NextRenderer | Action::PreviousRenderer => {
                let n = self.algos.len();
                let step = if action == Action::NextRenderer { 1 } else { n - 1 };
                let a = self.algos[(self.algo_index() + step) % n].clone();
                self.choose(a);
            }
            Action::NextMode => {
                self.mode = self.mode.next();
                self.submit(true);
            }
            Action::Orbit => self.orbit = !self.orbit,
            Action::Reset => {
                self.playing = false;
                self.orbit = false;
                self.set_camera(self.start);
            }
            Action::PathView(step) => {
                let n = self.path.len();
                self.path_index = (self.path_index + if step > 0 { 1 } else { n - 1 }) % n;
                self.set_camera(self.path[self.path_index]);
            }
            Action::Play => {
                self.playing = !self.playing;
                if self.playing {
                    self.set_camera(self.path[self.path_index]);
                }
            }
            Action::Screenshot => {
                let path = next_free("occult-shot", "png", &mut self.shot_count);
                self.pending_shot = Some(path);
                self.submit(false);
            }
            Action::Record => {
                if let Some(cameras) = self.recording.take() {
                    let path = self
                        .record_to
                        .clone()
                        .unwrap_or_else(|| next_free("occult-path", "json", &mut 0));
                    match occult_scenes::path::write_path_json(&path, &cameras) {
                        Ok(()) => self.say(format!("wrote {} cameras to {}", cameras.len(), path.display())),
                        Err(e) => self.say(format!("cannot write the path: {e}")),
                    }
                } else {
                    self.recording = Some(vec![self.fly.camera]);
                }
            }
            Action::Stats => self.show_stats = !self.show_stats,
            Action::Help => self.show_help = !self.show_help,
            Action::Quit => event_loop.exit(),
        }
        if let Some(w) = &self.window {
            w.request_redraw();
        }
    }

    fn say(&mut self, message: String) {
        self.message = Some((message, Instant::now()));
    }

    /// Moves the camera for held keys and orbiting over `dt` seconds.
    fn tick(&mut self, dt: f32) {
        if self.held.is_empty() && !self.orbit {
            return;
        }
        let before = self.fly.camera;
        self.apply_held(dt);
        if self.orbit {
            self.fly.orbit(ORBIT_DEG_PER_S * dt);
        }
        if self.fly.camera != before {
            self.submit(true);
        }
    }

    fn apply_held(&mut self, dt: f32) {
        let d = self.fly.speed * dt;
        let turn = LOOK_DEG_PER_S * dt;
        let held: Vec<Action> = self.held.iter().copied().collect();
        for action in held {
            match action {
                Action::Fly(Direction::Forward) => self.fly.step(d, 0.0, 0.0),
                Action::Fly(Direction::Back) => self.fly.step(-d, 0.0, 0.0),
                Action::Fly(Direction::Left) => self.fly.step(0.0, -d, 0.0),
                Action::Fly(Direction::Right) => self.fly.step(0.0, d, 0.0),
                Action::Fly(Direction::Up) => self.fly.step(0.0, 0.0, d),
                Action::Fly(Direction::Down) => self.fly.step(0.0, 0.0, -d),
                Action::Look(Direction::Left) => self.fly.turn(-turn, 0.0),
                Action::Look(Direction::Right) => self.fly.turn(turn, 0.0),
                Action::Look(Direction::Up) => self.fly.turn(0.0, turn),
                Action::Look(Direction::Down) => self.fly.turn(0.0, -turn),
                _ => {}
            }
        }
    }

    /// A frame from the worker.
    fn shown(&mut self, event_loop: &ActiveEventLoop, frame: Box<Shown>) {
        self.frames_shown += 1;
        let now = Instant::now();
        self.frame_times.push(now);
        if self.frame_times.len() > 30 {
            self.frame_times.remove(0);
        }
        // A frame counts for an input once it was finished after the input: one finished
        // before, still on its way to the window, is not a frame the input could be in.
        let mut still = Vec::with_capacity(self.pending_inputs.len());
        for (id, at, seen) in self.pending_inputs.drain(..) {
            let seen = seen + u32::from(frame.finished > at);
            if frame.id >= id {
                self.latencies.push((seen.max(1), (now - at).as_secs_f64() * 1e3));
            } else {
                still.push((id, at, seen));
            }
        }
        self.pending_inputs = still;
        if frame.label == self.algo.label() {
            self.building = None;
        }
        if let Some(shot) = &frame.shot {
            self.pending_shot = None;
            match shot {
                Ok(p) => self.say(format!("wrote {}", p.display())),
                Err(e) => {
                    let e = e.clone();
                    self.say(e.clone());
                    if self.script.is_some() {
                        self.fail(event_loop, anyhow!(e));
                    }
                }
            }
        }
        let caught_up = frame.id >= self.next_id;
        if let Some(Wait::Fly { render_ms, .. }) = self.script.as_mut().and_then(|r| r.wait.as_mut().map(|w| &mut w.0))
        {
            render_ms.push(frame.frame_ms);
        }
        self.last = Some(frame);
        if self.playing && caught_up {
            if self.path_index + 1 < self.path.len() {
                self.path_index += 1;
                self.set_camera(self.path[self.path_index]);
            } else {
                self.playing = false;
            }
        }
        if let Some(w) = &self.window {
            w.request_redraw();
        }
    }

    /// True while the window waits for a frame of a newer state than it shows (or for its
    /// first frame).
    fn awaiting_frame(&self) -> bool {
        self.last.as_ref().map_or(self.next_id > 0, |f| f.id < self.next_id)
    }

    /// True when the last frame shows the current state, drawn by the chosen renderer.
    fn current(&self) -> bool {
        self.last.as_ref().is_some_and(|f| {
            f.id >= self.next_id
                && f.label == self.algo.label()
                && f.mode == self.mode
                && (self.mode != Mode::Exactness || f.differing_pixels.is_some())
        })
    }

    /// Runs script commands until one has to wait.
    fn pump(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_none() {
            return;
        }
        loop {
            let Some(run) = self.script.as_mut() else {
                return;
            };
            if let Some((wait, since, line)) = run.wait.take() {
                match self.waited(wait) {
                    Ok(None) => {}
                    Ok(Some(wait)) => {
                        if since.elapsed() > SCRIPT_TIMEOUT {
                            let e = anyhow!("script line {line}: no frame after {} s", SCRIPT_TIMEOUT.as_secs());
                            self.fail(event_loop, e);
                            return;
                        }
                        if let Some(run) = self.script.as_mut() {
                            run.wait = Some((wait, since, line));
                        }
                        return;
                    }
                    Err(e) => {
                        self.fail(event_loop, e.context(format!("script line {line}")));
                        return;
                    }
                }
                continue;
            }
            let Some(run) = self.script.as_mut() else {
                return;
            };
            let Some((line, command)) = run.commands.get(run.next).cloned() else {
                event_loop.exit();
                return;
            };
            run.next += 1;
            match self.execute(event_loop, command) {
                Ok(Some(wait)) => {
                    if let Some(run) = self.script.as_mut() {
                        run.wait = Some((wait, Instant::now(), line));
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    self.fail(event_loop, e.context(format!("script line {line}")));
                    return;
                }
            }
        }
    }

    /// `None` when `wait` is over, else the wait still to do.
    fn waited(&mut self, wait: Wait) -> Result<Option<Wait>> {
        Ok(match wait {
            Wait::Frame => (!self.current()).then_some(Wait::Frame),
            Wait::Progress => {
                let under_way = self
                    .worker
                    .in_flight()
                    .is_some_and(|(id, progress, _)| id >= self.next_id && progress > 0.0);
                (!under_way && !self.current()).then_some(Wait::Progress)
            }
            Wait::Shot => self.pending_shot.is_some().then_some(Wait::Shot),
            Wait::Capture(path) => {
                if !self.current() {
                    return Ok(Some(Wait::Capture(path)));
                }
                self.capture(&path)?;
                None
            }
            Wait::Stats(path) => {
                let Some(frame) = self.last.as_ref().filter(|_| self.current()) else {
                    return Ok(Some(Wait::Stats(path)));
                };
                let s = &frame.stats;
                let json = serde_json::json!({
                    "renderer": frame.label,
                    "mode": frame.mode.name(),
                    "width": frame.width,
                    "height": frame.height,
                    "frame_ms": frame.frame_ms,
                    "render_ms": frame.render_ms,
                    "phases_ms": s.phases_ms(),
                    "triangles_submitted": s.triangles_submitted,
                    "triangles_rasterized": s.triangles_rasterized,
                    "triangles_visible": frame.triangles_visible,
                    "differing_pixels": frame.differing_pixels,
                    "counters": s.counters,
                });
                output::write_json(&path, &json)?;
                None
            }
            Wait::Until(t) => (Instant::now() < t).then_some(Wait::Until(t)),
            Wait::Fly {
                until_frame,
                start,
                frames_at_start,
                render_ms,
            } => {
                if self.frames_shown < until_frame {
                    return Ok(Some(Wait::Fly {
                        until_frame,
                        start,
                        frames_at_start,
                        render_ms,
                    }));
                }
                let frames = self.frames_shown - frames_at_start;
                let s = start.elapsed().as_secs_f64();
                let mean = render_ms.iter().sum::<f64>() / render_ms.len().max(1) as f64;
                self.flights.push(format!(
                    "fly: {} with {} at {}x{}: {frames} frames in {:.2} s, {:.1} frames per second (mean frame {:.1} ms)",
                    self.scene.spec,
                    self.algo.label(),
                    self.size.width,
                    self.size.height,
                    s,
                    frames as f64 / s,
                    mean
                ));
                self.held.clear();
                None
            }
        })
    }

    /// Writes the window as it is now, overlays included, to `path` as PNG.
    fn capture(&mut self, path: &Path) -> Result<()> {
        self.compose();
        let (w, h) = self.composed_size;
        let raw: Vec<u8> = self
            .composed
            .iter()
            .flat_map(|p| [(p >> 16) as u8, (p >> 8) as u8, *p as u8])
            .collect();
        let image = image::RgbImage::from_raw(w, h, raw).context("the window's pixels")?;
        image
            .save_with_format(path, image::ImageFormat::Png)
            .with_context(|| format!("cannot write '{}'", path.display()))
    }

    /// Does one script command; returns what it waits for.
    fn execute(&mut self, event_loop: &ActiveEventLoop, command: Command) -> Result<Option<Wait>> {
        Ok(match command {
            Command::Camera { eye, target, up } => {
                let mut c = self.fly.camera;
                c.eye = eye;
                c.target = target;
                c.up = up.unwrap_or(c.up);
                c.validate()?;
                self.set_camera(c);
                None
            }
            Command::View(view) => {
                let c = view
                    .spec
                    .camera(&self.scene.scene, &self.scene.default_camera)
                    .with_context(|| format!("view '{}'", view.text))?;
                c.validate()?;
                self.set_camera(c);
                None
            }
            Command::Move { forward, right, up } => {
                self.fly.step(forward, right, up);
                self.submit(true);
                None
            }
            Command::Turn { yaw_deg, pitch_deg } => {
                self.fly.turn(yaw_deg, pitch_deg);
                self.submit(true);
                None
            }
            Command::Key(name) => {
                let action = Action::from_name(&name).with_context(|| format!("unknown key '{name}'"))?;
                if action.is_held() {
                    self.held.insert(action);
                    self.apply_held(SCRIPT_PRESS_S);
                    self.held.remove(&action);
                    self.submit(true);
                } else {
                    self.act(event_loop, action, true);
                }
                None
            }
            Command::Algo(spec) => {
                self.choose(spec);
                None
            }
            Command::Mode(mode) => {
                self.mode = mode;
                self.submit(true);
                None
            }
            Command::Size(size) => {
                self.size = size;
                if let Some(w) = &self.window {
                    let _ = w.request_inner_size(PhysicalSize::new(size.width, size.height));
                }
                self.submit(true);
                None
            }
            Command::WaitFrame => Some(Wait::Frame),
            Command::WaitProgress => Some(Wait::Progress),
            Command::Screenshot(path) => {
                output::check_output(&path)?;
                self.pending_shot = Some(path);
                self.submit(false);
                Some(Wait::Shot)
            }
            Command::Capture(path) => {
                output::check_output(&path)?;
                Some(Wait::Capture(path))
            }
            Command::CaptureNow(path) => {
                output::check_output(&path)?;
                self.capture(&path)?;
                None
            }
            Command::Stats(path) => {
                output::check_output(&path)?;
                Some(Wait::Stats(path))
            }
            Command::RecordStart => {
                self.recording = Some(vec![self.fly.camera]);
                None
            }
            Command::RecordStop(path) => {
                let cameras = self.recording.take().context("'record stop' without 'record start'")?;
                occult_scenes::path::write_path_json(&path, &cameras)?;
                None
            }
            Command::Fly(frames) => {
                self.held.insert(Action::Fly(Direction::Forward));
                self.held.insert(Action::Look(Direction::Right));
                Some(Wait::Fly {
                    until_frame: self.frames_shown + u64::from(frames),
                    start: Instant::now(),
                    frames_at_start: self.frames_shown,
                    render_ms: Vec::new(),
                })
            }
            Command::Sleep(ms) => Some(Wait::Until(Instant::now() + Duration::from_millis(ms))),
            Command::Exit => {
                event_loop.exit();
                if let Some(run) = self.script.as_mut() {
                    run.next = run.commands.len();
                }
                None
            }
        })
    }

    /// The frame and the overlays into `composed`, at the window's size.
    fn compose(&mut self) {
        let (w, h) = self
            .window
            .as_ref()
            .map(|w| {
                let s = w.inner_size();
                (s.width.max(1), s.height.max(1))
            })
            .unwrap_or((self.size.width, self.size.height));
        self.composed_size = (w, h);
        self.composed.clear();
        self.composed.resize(w as usize * h as usize, 0);
        if let Some(f) = &self.last {
            let rows = f.height.min(h) as usize;
            let cols = f.width.min(w) as usize;
            for y in 0..rows {
                let src = &f.pixels[y * f.width as usize..][..cols];
                self.composed[y * w as usize..][..cols].copy_from_slice(src);
            }
        }
        let width = w as usize;
        // The frame in flight's progress: a bar along the window's bottom edge.
        if let Some((_, progress, ran)) = self.worker.in_flight() {
            if ran >= PROGRESS_AFTER && self.awaiting_frame() {
                let filled = (f64::from(progress) * f64::from(w)).round() as usize;
                for row in self.composed.chunks_exact_mut(width).rev().take(PROGRESS_BAR_ROWS) {
                    for (x, p) in row.iter_mut().enumerate() {
                        *p = if x < filled { 0x00ff_d040 } else { 0x0040_4040 };
                    }
                }
            }
        }
        let mut composed = std::mem::take(&mut self.composed);
        if self.show_stats {
            let lines = self.stats_lines();
            self.text.panel(&mut composed, width, 8, 8, false, &lines);
            let list = self.renderer_lines();
            self.text.panel(&mut composed, width, w as i32 - 8, 8, true, &list);
        }
        if self.show_help {
            let lines: Vec<(String, u32)> = HELP
                .iter()
                .enumerate()
                .map(|(i, l)| (l.to_string(), if i == 0 { 0x00ff_d040 } else { 0x00ff_ffff }))
                .collect();
            let line_height = self.text.line_height();
            let help_h = line_height * lines.len() as i32;
            let help_w = HELP
                .iter()
                .map(|l| {
                    l.split_once('\t')
                        .map_or(0, |(a, b)| self.text.width(a) + self.text.width(b))
                })
                .max()
                .unwrap_or(0);
            let x = (w as i32 - help_w - 40).max(0) / 2;
            let y = (h as i32 - help_h).max(0) / 2;
            self.text.panel(&mut composed, width, x, y, false, &lines);
        } else {
            let hint = vec![("H: help".to_string(), 0x00c0_c0c0)];
            let y = h as i32 - self.text.line_height() - 20;
            self.text.panel(&mut composed, width, 8, y, false, &hint);
        }
        self.composed = composed;
    }

    fn stats_lines(&self) -> Vec<(String, u32)> {
        const WHITE: u32 = 0x00ff_ffff;
        const DIM: u32 = 0x00c0_c0c0;
        let mut lines = Vec::new();
        let fps = match (self.frame_times.first(), self.frame_times.last()) {
            (Some(a), Some(b)) if self.frame_times.len() > 1 && b > a => {
                format!("{:.1}", (self.frame_times.len() - 1) as f64 / (*b - *a).as_secs_f64())
            }
            _ => "-".to_string(),
        };
        match &self.last {
            Some(f) => {
                let s = &f.stats;
                lines.push((
                    format!(
                        "{}  [{}]  {}x{}  frame {} ms  render {} ms  {} fps",
                        f.label,
                        f.mode.name(),
                        f.width,
                        f.height,
                        output::millis(f.frame_ms),
                        output::millis(f.render_ms),
                        fps
                    ),
                    WHITE,
                ));
                let phases: Vec<String> = s
                    .phases_ms()
                    .iter()
                    .map(|(p, ms)| format!("{p} {}", output::millis(*ms)))
                    .collect();
                lines.push((format!("phases (ms): {}", phases.join(", ")), DIM));
                lines.push((
                    format!(
                        "triangles: {} submitted, {} rasterized, {} visible",
                        output::count(s.triangles_submitted as f64),
                        output::count(s.triangles_rasterized as f64),
                        output::count(f.triangles_visible as f64)
                    ),
                    WHITE,
                ));
                let mut counters: Vec<String> = s
                    .fixed_counters()
                    .iter()
                    .skip(2)
                    .filter(|(_, v)| *v > 0)
                    .map(|(k, v)| format!("{} {}", k.replace('_', " "), output::count(*v as f64)))
                    .collect();
                counters.extend(
                    s.counters
                        .0
                        .iter()
                        .map(|(k, v)| format!("{} {}", k.replace('_', " "), output::count(*v as f64))),
                );
                for chunk in counters.chunks(3) {
                    lines.push((chunk.join(", "), DIM));
                }
                if f.mode == Mode::Exactness {
                    lines.push(match f.differing_pixels {
                        Some(0) => ("exact: every pixel as zbuffer's".to_string(), 0x0060_ff60),
                        Some(n) => (
                            format!("{} pixels differ from zbuffer's (magenta)", output::count(n as f64)),
                            0x00ff_60ff,
                        ),
                        None => ("exactness: building zbuffer".to_string(), DIM),
                    });
                }
            }
            None => lines.push(("no frame yet".to_string(), WHITE)),
        }
        let c = &self.fly.camera;
        lines.push((
            format!(
                "eye {:.2},{:.2},{:.2}  speed {}/s{}{}",
                c.eye.x,
                c.eye.y,
                c.eye.z,
                output::count(f64::from(self.fly.speed)),
                if self.orbit { "  orbiting" } else { "" },
                if self.playing { "  playing the path" } else { "" }
            ),
            DIM,
        ));
        if let Some((label, since)) = &self.building {
            let spin = SPINNER[(since.elapsed().as_millis() / 120) as usize % SPINNER.len()];
            let showing = self.last.as_ref().map_or("nothing".to_string(), |f| f.label.clone());
            lines.push((
                format!(
                    "{spin} building {label} ({:.1} s); showing {showing}",
                    since.elapsed().as_secs_f64()
                ),
                0x00ff_d040,
            ));
        }
        if self.awaiting_frame() {
            let spin = SPINNER[(self.last_tick.elapsed().as_millis() / 120) as usize % SPINNER.len()];
            let line = match self.worker.in_flight() {
                Some((id, progress, ran)) => format!(
                    "{spin} rendering {:.0} % ({:.1} s){}",
                    progress * 100.0,
                    ran.as_secs_f64(),
                    if id < self.next_id { "; a newer view waits" } else { "" }
                ),
                None => format!("{spin} rendering"),
            };
            lines.push((line, DIM));
        }
        if self.frames_cancelled > 0 {
            lines.push((format!("frames cancelled: {}", self.frames_cancelled), DIM));
        }
        if let Some(cameras) = &self.recording {
            lines.push((format!("recording: {} cameras (C stops)", cameras.len()), 0x00ff_6060));
        }
        if let Some((m, at)) = &self.message {
            if at.elapsed() < Duration::from_secs(5) {
                lines.push((m.clone(), 0x00ff_d040));
            }
        }
        lines
    }

    fn renderer_lines(&self) -> Vec<(String, u32)> {
        let current = self.algo_index();
        self.algos
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let key = if i < 9 { format!("{}", i + 1) } else { " ".to_string() };
                if i == current {
                    (format!("> {key} {}", a.label()), 0x00ff_d040)
                } else {
                    (format!("  {key} {}", a.label()), 0x00c0_c0c0)
                }
            })
            .collect()
    }

    fn present(&mut self) -> Result<()> {
        self.compose();
        let (w, h) = self.composed_size;
        let Some(surface) = self.surface.as_mut() else {
            return Ok(());
        };
        let (Some(nw), Some(nh)) = (NonZeroU32::new(w), NonZeroU32::new(h)) else {
            return Ok(());
        };
        surface
            .resize(nw, nh)
            .map_err(|e| anyhow!("cannot size the window's buffer: {e}"))?;
        let mut buffer = surface.buffer_mut().map_err(|e| anyhow!("no window buffer: {e}"))?;
        if buffer.len() == self.composed.len() {
            buffer.copy_from_slice(&self.composed);
        }
        buffer.present().map_err(|e| anyhow!("cannot show the frame: {e}"))
    }
}

impl ApplicationHandler<Event> for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let attributes = Window::default_attributes()
            .with_title(format!("occult view: {}", self.scene.spec))
            .with_inner_size(PhysicalSize::new(self.size.width, self.size.height));
        let window = match event_loop.create_window(attributes) {
            Ok(w) => Arc::new(w),
            Err(e) => return self.fail(event_loop, super::no_display(e)),
        };
        let surface = softbuffer::Context::new(Arc::clone(&window))
            .and_then(|context| softbuffer::Surface::new(&context, Arc::clone(&window)));
        match surface {
            Ok(s) => self.surface = Some(s),
            Err(e) => return self.fail(event_loop, super::no_display(e)),
        }
        self.window = Some(window);
        self.submit(false);
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.present() {
                    self.fail(event_loop, e);
                }
            }
            WindowEvent::Resized(size) => {
                // A script fixes its frame size (`size`); a person's resize resizes frames.
                let size = Size {
                    width: size.width,
                    height: size.height,
                };
                if self.script.is_none()
                    && size != self.size
                    && occult_core::check_resolution(size.width, size.height).is_ok()
                {
                    self.size = size;
                    self.submit(false);
                }
                if let Some(w) = &self.window {
                    w.request_redraw();
                }
            }
            WindowEvent::ModifiersChanged(m) => self.shift = m.state().shift_key(),
            WindowEvent::KeyboardInput { event, .. } => {
                if event.repeat {
                    return;
                }
                if let PhysicalKey::Code(code) = event.physical_key {
                    if let Some(action) = Action::from_key(code, self.shift) {
                        self.act(event_loop, action, event.state == ElementState::Pressed);
                    }
                }
            }
            WindowEvent::Focused(false) => self.held.clear(),
            WindowEvent::MouseInput { state, .. } => {
                if state == ElementState::Pressed {
                    self.buttons_down += 1;
                } else {
                    self.buttons_down = self.buttons_down.saturating_sub(1);
                }
            }
            WindowEvent::CursorMoved { position, .. } => {
                let (x, y) = (position.x, position.y);
                if let (Some((px, py)), true) = (self.cursor, self.buttons_down > 0) {
                    let (dx, dy) = ((x - px) as f32, (y - py) as f32);
                    self.fly.turn(dx * MOUSE_DEG_PER_PX, -dy * MOUSE_DEG_PER_PX);
                    self.submit(true);
                }
                self.cursor = Some((x, y));
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => (p.y / 40.0) as f32,
                };
                self.fly.scale_speed(steps);
                self.say(format!("speed {:.3} units/s", self.fly.speed));
                if let Some(w) = &self.window {
                    w.request_redraw();
                }
            }
            _ => {}
        }
    }

    fn user_event(&mut self, event_loop: &ActiveEventLoop, event: Event) {
        match event {
            Event::Frame(frame) => self.shown(event_loop, frame),
            Event::Cancelled => self.frames_cancelled += 1,
            Event::Built { label, ms } => {
                self.say(format!("built {label} in {} ms", output::millis(ms)));
                if self.building.as_ref().is_some_and(|(b, _)| *b == label) {
                    self.building = None;
                }
                self.built.insert(label);
            }
            Event::Failed { label, error } => {
                if self.script.is_some() {
                    return self.fail(event_loop, anyhow!(error));
                }
                self.say(error);
                if label == self.algo.label() {
                    self.building = None;
                    if let Some(previous) = self.last.as_ref().map(|f| f.label.clone()) {
                        if let Some(a) = self.algos.iter().find(|a| a.label() == previous).cloned() {
                            self.algo = a;
                        }
                    }
                }
            }
        }
        self.pump(event_loop);
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        let now = Instant::now();
        let dt = (now - self.last_tick).min(Duration::from_millis(100)).as_secs_f32();
        if now - self.last_tick >= TICK {
            self.last_tick = now;
            let shooting = self
                .script
                .as_ref()
                .is_some_and(|r| matches!(r.wait, Some((Wait::Shot, _, _))));
            if !shooting {
                self.tick(dt);
            }
            let rendering = self.awaiting_frame();
            if rendering {
                // A slow frame of an older state is cancelled once due, input or not.
                self.worker.supersede();
            }
            if self.building.is_some() || self.message.is_some() || rendering {
                if let Some(w) = &self.window {
                    w.request_redraw();
                }
            }
        }
        self.pump(event_loop);
        let animating = !self.held.is_empty()
            || self.orbit
            || self.awaiting_frame()
            || self.building.is_some()
            || self.script.as_ref().is_some_and(|r| r.wait.is_some())
            || self
                .message
                .as_ref()
                .is_some_and(|(_, at)| at.elapsed() < Duration::from_secs(6));
        event_loop.set_control_flow(if animating {
            ControlFlow::WaitUntil(self.last_tick + TICK)
        } else {
            ControlFlow::Wait
        });
    }
}

/// `stem-N.ext` in the current directory, the first N from `*count` on that is free.
fn next_free(stem: &str, ext: &str, count: &mut u32) -> PathBuf {
    loop {
        *count += 1;
        let p = PathBuf::from(format!("{stem}-{count}.{ext}"));
        if !p.exists() {
            return p;
        }
    }
}

/// The latency report: frames until the first frame that reflects an input.
fn latency_line(latencies: &[(u32, f64)], frames_shown: u64) -> String {
    if latencies.is_empty() {
        return format!("frames shown: {frames_shown}; input latency: no input measured");
    }
    let n = latencies.len() as f64;
    let mean_frames = latencies.iter().map(|l| f64::from(l.0)).sum::<f64>() / n;
    let max_frames = latencies.iter().map(|l| l.0).max().unwrap_or(0);
    let mean_ms = latencies.iter().map(|l| l.1).sum::<f64>() / n;
    format!(
        "frames shown: {frames_shown}; input latency over {} inputs: mean {mean_frames:.2} frames (max {max_frames}), mean {mean_ms:.1} ms",
        latencies.len()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latency_lines() {
        assert!(latency_line(&[], 3).contains("no input"));
        let l = latency_line(&[(1, 10.0), (2, 30.0)], 5);
        assert!(l.contains("mean 1.50 frames (max 2), mean 20.0 ms"), "{l}");
    }
}
