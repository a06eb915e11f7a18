//! The script language of `occult view --script FILE`: one command a line, `#` starts a
//! comment. It drives the window as a person would (key presses go through the same handler
//! as the keyboard's), and waits where a person would look, so that a script's screenshots
//! are the same on every run.
//!
//! | command | does |
//! | --- | --- |
//! | `camera eye X,Y,Z target X,Y,Z [up X,Y,Z]` | sets the camera (fov, near and far kept) |
//! | `view VIEW` | the camera of a view, as `occult render --view` (`default`, `circle:8:3`, `cams.json:2`) |
//! | `move forward|right|up DIST` | moves the camera along its own axes, world units |
//! | `turn YAW PITCH` | turns the view right and up, degrees |
//! | `key NAME` | presses and releases a key (`w`, `3`, `tab`, `shift+tab`, `m`, `f1`, ...) |
//! | `algo SPEC` | switches to a renderer spec, as `--algo` |
//! | `mode color|depth|items|exactness` | the display mode |
//! | `size WxH` | the frame size (the window is resized) |
//! | `wait-frame` | waits for a frame of the current state, drawn by the chosen renderer |
//! | `wait-progress` | waits until a frame of the current state is under way (has reported progress) or shown |
//! | `screenshot FILE` | a frame of the current state to PNG: the pixels `occult render` writes |
//! | `capture FILE` | the window as shown, overlays included, to PNG |
//! | `capture-now FILE` | the same at once, without waiting for a frame of the current state (a frame in flight's progress shows) |
//! | `stats FILE` | what the overlay shows of a frame of the current state, as JSON |
//! | `record start` / `record stop FILE` | records the flown cameras; writes them as a path file |
//! | `fly FRAMES` | flies forward and turning, input every 10 ms, until FRAMES frames are shown; prints fps |
//! | `sleep MS` | waits |
//! | `exit` | closes the window (also at the end of the script) |

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use occult_core::Vec3;
use occult_render::AlgoSpec;

use super::worker::Mode;
use crate::args::{parse_algorithm, parse_size, parse_vec3, parse_view, Size, ViewArg};

/// One command of a script.
#[derive(Clone, Debug)]
pub enum Command {
    /// Sets eye and target (and up).
    Camera {
        /// Eye, world.
        eye: Vec3,
        /// Target, world.
        target: Vec3,
        /// Up, if given.
        up: Option<Vec3>,
    },
    /// The camera of a view spec.
    View(ViewArg),
    /// Moves along the camera's axes, world units.
    Move {
        /// Along the view direction.
        forward: f32,
        /// To the right.
        right: f32,
        /// Along up.
        up: f32,
    },
    /// Turns right and up, degrees.
    Turn {
        /// Right.
        yaw_deg: f32,
        /// Up.
        pitch_deg: f32,
    },
    /// A key pressed and released.
    Key(String),
    /// A renderer spec.
    Algo(AlgoSpec),
    /// A display mode.
    Mode(Mode),
    /// A frame size.
    Size(Size),
    /// Waits for a frame of the current state.
    WaitFrame,
    /// Waits for a frame of the current state to be under way (or shown).
    WaitProgress,
    /// A frame's colors to PNG.
    Screenshot(PathBuf),
    /// The window's pixels to PNG.
    Capture(PathBuf),
    /// The window's pixels to PNG at once.
    CaptureNow(PathBuf),
    /// The frame's statistics to JSON.
    Stats(PathBuf),
    /// Starts recording the flown cameras.
    RecordStart,
    /// Stops recording and writes the path file.
    RecordStop(PathBuf),
    /// Flies until this many frames were shown.
    Fly(u32),
    /// Waits this many milliseconds.
    Sleep(u64),
    /// Closes the window.
    Exit,
}

/// A parsed script: each command with its line number (from 1).
#[derive(Clone, Debug, Default)]
pub struct Script {
    /// The commands, with their line numbers.
    pub commands: Vec<(usize, Command)>,
}

impl Script {
    /// Reads and parses the script at `path`.
    ///
    /// # Errors
    /// An unreadable file; the first bad line, by number.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read script '{}'", path.display()))?;
        Self::parse(&text).with_context(|| format!("script '{}'", path.display()))
    }

    /// Parses a script's text.
    ///
    /// # Errors
    /// The first bad line, by number, naming the problem.
    pub fn parse(text: &str) -> Result<Self> {
        let mut commands = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let command = parse_line(line).with_context(|| format!("line {}: '{line}'", i + 1))?;
            commands.push((i + 1, command));
        }
        Ok(Self { commands })
    }
}

fn parse_line(line: &str) -> Result<Command> {
    let words: Vec<&str> = line.split_whitespace().collect();
    let (verb, args) = words.split_first().context("empty command")?;
    let one = || -> Result<&str> {
        match args {
            [a] => Ok(*a),
            _ => bail!("'{verb}' takes one argument"),
        }
    };
    let number = |s: &str| -> Result<f32> {
        s.parse::<f32>()
            .ok()
            .filter(|v| v.is_finite())
            .with_context(|| format!("expected a finite number, not '{s}'"))
    };
    Ok(match *verb {
        "camera" => parse_camera(args)?,
        "view" => Command::View(parse_view(one()?).map_err(anyhow::Error::msg)?),
        "move" => {
            let [axis, dist] = args else {
                bail!("expected 'move forward|right|up DIST'");
            };
            let d = number(dist)?;
            match *axis {
                "forward" => Command::Move { forward: d, right: 0.0, up: 0.0 },
                "right" => Command::Move { forward: 0.0, right: d, up: 0.0 },
                "up" => Command::Move { forward: 0.0, right: 0.0, up: d },
                other => bail!("unknown axis '{other}' (forward, right, up)"),
            }
        }
        "turn" => {
            let [yaw, pitch] = args else {
                bail!("expected 'turn YAW PITCH' in degrees");
            };
            Command::Turn {
                yaw_deg: number(yaw)?,
                pitch_deg: number(pitch)?,
            }
        }
        "key" => {
            let name = one()?.to_ascii_lowercase();
            if super::keys::Action::from_name(&name).is_none() {
                bail!("unknown key '{name}' (press H in the window for the keys)");
            }
            Command::Key(name)
        }
        "algo" => Command::Algo(parse_algorithm(one()?).map_err(anyhow::Error::msg)?),
        "mode" => {
            let m = one()?;
            Command::Mode(Mode::parse(m).with_context(|| format!("unknown mode '{m}' (color, depth, items, exactness)"))?)
        }
        "size" => Command::Size(parse_size(one()?).map_err(anyhow::Error::msg)?),
        "wait-frame" if args.is_empty() => Command::WaitFrame,
        "wait-progress" if args.is_empty() => Command::WaitProgress,
        "screenshot" => Command::Screenshot(PathBuf::from(one()?)),
        "capture" => Command::Capture(PathBuf::from(one()?)),
        "capture-now" => Command::CaptureNow(PathBuf::from(one()?)),
        "stats" => Command::Stats(PathBuf::from(one()?)),
        "record" => match args {
            ["start"] => Command::RecordStart,
            ["stop", file] => Command::RecordStop(PathBuf::from(file)),
            _ => bail!("expected 'record start' or 'record stop FILE'"),
        },
        "fly" => {
            let n: u32 = one()?.parse().ok().filter(|&n| n > 0).context("expected a frame count above 0")?;
            Command::Fly(n)
        }
        "sleep" => Command::Sleep(one()?.parse().context("expected milliseconds")?),
        "exit" if args.is_empty() => Command::Exit,
        "wait-frame" | "wait-progress" | "exit" => bail!("'{verb}' takes no argument"),
        other => bail!(
            "unknown command '{other}' (camera, view, move, turn, key, algo, mode, size, wait-frame, wait-progress, screenshot, capture, capture-now, stats, record, fly, sleep, exit)"
        ),
    })
}

fn parse_camera(args: &[&str]) -> Result<Command> {
    let mut eye = None;
    let mut target = None;
    let mut up = None;
    for pair in args.chunks(2) {
        let [key, value] = pair else {
            bail!("expected 'camera eye X,Y,Z target X,Y,Z [up X,Y,Z]'");
        };
        let v = parse_vec3(value).map_err(anyhow::Error::msg)?;
        match *key {
            "eye" => eye = Some(v),
            "target" => target = Some(v),
            "up" => up = Some(v),
            other => bail!("unknown camera field '{other}' (eye, target, up)"),
        }
    }
    match (eye, target) {
        (Some(eye), Some(target)) => Ok(Command::Camera { eye, target, up }),
        _ => bail!("'camera' needs both eye and target"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_command_parses() {
        let s = Script::parse(
            "# a comment\n\ncamera eye 1,2,3 target 0,0,0 up 0,0,1\nview circle:8:3\nmove forward 2.5\nturn 10 -5\n\
             key 3\nkey shift+tab\nalgo hzb:temporal=off\nmode depth\nsize 64x48\nwait-frame\nwait-progress\nscreenshot a.png # shot\n\
             capture b.png\ncapture-now d.png\nstats c.json\nrecord start\nrecord stop p.json\nfly 10\nsleep 5\nexit\n",
        )
        .expect("a good script parses");
        assert_eq!(s.commands.len(), 20);
        assert_eq!(s.commands[0].0, 3, "line numbers count comments and blanks");
    }

    #[test]
    fn bad_lines_are_named() {
        for (text, needle) in [
            ("camera eye 1,2,3", "needs both"),
            ("view circle:8:9", "index 9"),
            ("move sideways 1", "sideways"),
            ("turn 1", "YAW PITCH"),
            ("key nosuchkey", "nosuchkey"),
            ("algo warp", "warp"),
            ("mode colour", "colour"),
            ("size 0x0", "0x0"),
            ("fly 0", "above 0"),
            ("jump", "unknown command"),
            ("exit now", "no argument"),
            ("wait-progress 5", "no argument"),
            ("move forward nan", "finite"),
        ] {
            let e = format!("{:#}", Script::parse(&format!("wait-frame\n{text}\n")).unwrap_err());
            assert!(e.contains("line 2") && e.contains(needle), "{text}: {e}");
        }
    }
}
