//! `occult view`: a window onto a scene, flown with the keyboard and mouse, drawn by any
//! renderer, switched live.
//!
//! Three threads and a few short ones:
//! - the window thread ([`app`]) handles input, moves the camera, and shows the last
//!   finished frame with the text overlays; it never waits on a renderer;
//! - the render thread ([`worker`]) draws the latest request, shades it and turns it into
//!   the pixels of the chosen display mode; requests that arrive while it draws replace each
//!   other, so a slow frame delays the next by at most one frame;
//! - each renderer is built on a thread of its own the first time it is chosen; until it is
//!   ready the previous renderer keeps drawing, and the overlay shows a spinner.
//!
//! `--script FILE` ([`script`]) drives the same window without a person: the tests run it
//! under Xvfb. A screenshot is written by the render thread from the shaded frame with the
//! function `occult render` uses, so that it holds the same pixels.
//!
//! The window is X11 (winit and softbuffer load libX11 and libxcb at run time); with no
//! display the command says so on one line and names `occult render` and `occult walk`.

mod app;
mod fly;
mod keys;
mod overlay;
mod script;
mod worker;

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use occult_render::{AlgoSpec, Algorithm};

use crate::args::{
    parse_algorithms, parse_path, parse_scene, parse_size, AlgorithmList, CameraArgs, PathArg, SceneArg, Size,
};
use crate::scene;

/// `occult view`.
#[derive(Debug, Args)]
pub struct ViewArgs {
    /// Scene: a generator spec (`city:blocks=8`, see `occult scenes`) or a file (.obj, .ply,
    /// .gltf, .glb).
    #[arg(value_name = "SCENE", value_parser = parse_scene)]
    pub scene: SceneArg,
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Renderers to switch between (keys 1-9, Tab), comma-separated, each with its settings;
    /// the first is shown first. Every other renderer follows with default settings.
    #[arg(long, value_name = "A,B,..", default_value = "frustum", value_parser = parse_algorithms)]
    pub algo: AlgorithmList,
    /// Frame size, WxH pixels (the window's first size; resizing the window resizes frames).
    #[arg(long, value_name = "WxH", default_value = "1280x720", value_parser = parse_size)]
    pub size: Size,
    /// The camera path that N and B step through and P plays (as `occult walk --path`).
    #[arg(long, value_name = "PATH", default_value = "circle:120", value_parser = parse_path)]
    pub path: PathArg,
    /// Run a script instead of waiting for a person (see docs/view.md): camera moves, key
    /// presses, screenshots, exit.
    #[arg(long, value_name = "FILE")]
    pub script: Option<PathBuf>,
    /// Where C writes the recorded camera path (JSON, as `--path` reads); default:
    /// `occult-path-N.json` in the current directory.
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,
}

/// The one line said when there is no display.
const NO_DISPLAY: &str = "occult view needs an X11 display";
const ALTERNATIVES: &str =
    "without one, use 'occult render' for a frame to PNG or 'occult walk' for a camera path's frames";

/// Runs the command.
pub fn run(a: ViewArgs) -> Result<()> {
    a.camera.overrides.check()?;
    let script = a.script.as_deref().map(script::Script::read).transpose()?;
    if let Some(p) = &a.record {
        crate::output::check_output(p)?;
    }
    if std::env::var_os("DISPLAY").is_none_or(|d| d.is_empty()) {
        bail!("{NO_DISPLAY}, and DISPLAY is not set; {ALTERNATIVES}");
    }
    let scene = scene::load(&a.scene)?;
    let start = scene::camera(&a.camera.view, &a.camera.overrides, &scene)?;
    let path = scene::path(&a.path, &scene)?;
    let mut algos: Vec<AlgoSpec> = a.algo.0.clone();
    for algorithm in Algorithm::all() {
        let spec = AlgoSpec::from(algorithm);
        if !algos.iter().any(|s| s.label() == spec.label()) {
            algos.push(spec);
        }
    }
    app::run(app::Setup {
        scene,
        start,
        path,
        algos,
        size: a.size,
        script,
        record_to: a.record,
    })
}

/// The error for a display that cannot be opened.
fn no_display(cause: impl std::fmt::Display) -> anyhow::Error {
    let display = std::env::var("DISPLAY").unwrap_or_default();
    // winit's errors open with the source location of the platform code: keep the reason.
    let cause = cause.to_string();
    let reason = cause.rsplit(": ").next().unwrap_or(&cause).trim();
    anyhow::anyhow!("{NO_DISPLAY}, and display '{display}' cannot be opened ({reason}); {ALTERNATIVES}")
}
