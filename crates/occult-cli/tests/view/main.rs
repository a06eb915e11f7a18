//! End-to-end tests of `occult view` (feature `view`): scripts drive a real window under a
//! virtual X server (Xvfb), one server per test. Without Xvfb the window tests say why and
//! pass; `.ci/run` installs it.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

/// Small scenes: fast on two cores.
const TERRAIN: &str = "terrain:g=24";
const CITY: &str = "city:blocks=1,detail=1,variants=2";
const SIZE: &str = "160x120";

/// An Xvfb server, stopped when dropped.
struct Xvfb {
    child: Child,
    display: String,
}

impl Xvfb {
    /// Starts `Xvfb :N` on a display number free for this test; `None` (with the reason
    /// printed) when Xvfb is not installed or does not start.
    fn start(test: &str) -> Option<Xvfb> {
        if Command::new("Xvfb")
            .arg("-help")
            .stderr(Stdio::null())
            .stdout(Stdio::null())
            .status()
            .is_err()
        {
            println!("skipped {test}: Xvfb is not installed (apt-get install xvfb)");
            return None;
        }
        // A display number per test and process, away from the usual :0 and :1: tests run
        // in parallel, and two servers must never race for one number.
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let base = 200 + (std::process::id() % 100) * 40;
        for _ in 0..8 {
            let n = base + NEXT.fetch_add(1, Ordering::Relaxed) % 40;
            if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists() || Path::new(&format!("/tmp/.X{n}-lock")).exists() {
                continue;
            }
            let display = format!(":{n}");
            let Ok(child) = Command::new("Xvfb")
                .args([display.as_str(), "-screen", "0", "1280x1024x24", "-nolisten", "tcp"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
            else {
                continue;
            };
            let mut server = Xvfb { child, display };
            let socket = PathBuf::from(format!("/tmp/.X11-unix/X{n}"));
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs(10) {
                // Our server is the one listening only while it still runs.
                if let Ok(Some(_)) = server.child.try_wait() {
                    break;
                }
                if socket.exists() {
                    std::thread::sleep(Duration::from_millis(100));
                    if let Ok(None) = server.child.try_wait() {
                        return Some(server);
                    }
                    break;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = server.child.kill();
        }
        println!("skipped {test}: Xvfb did not start");
        None
    }

    /// `occult view` on this display.
    fn view(&self, args: &[&str]) -> Output {
        Command::new(env!("CARGO_BIN_EXE_occult"))
            .arg("view")
            .args(args)
            .env("DISPLAY", &self.display)
            .output()
            .expect("the occult binary runs")
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn occult(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_occult"))
        .args(args)
        .output()
        .expect("the occult binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn assert_ok(out: &Output, what: &str) -> String {
    assert!(
        out.status.success(),
        "{what} failed: {}{}",
        text(&out.stderr),
        text(&out.stdout)
    );
    text(&out.stdout)
}

/// A fresh directory for one test's files.
fn scratch(test: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("occult-view-tests")
        .join(test);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("the test directory can be made");
    dir
}

fn s(p: &Path) -> &str {
    p.to_str().expect("test paths are UTF-8")
}

fn bytes(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// `occult render` of `view` with zbuffer, as PNG bytes.
fn render(dir: &Path, scene: &str, view: &str, name: &str) -> Vec<u8> {
    let out = dir.join(name);
    assert_ok(
        &occult(&[
            "render",
            "--scene",
            scene,
            "--view",
            view,
            "--size",
            SIZE,
            "--algo",
            "zbuffer",
            "--out",
            s(&out),
        ]),
        "occult render",
    );
    bytes(&out)
}

#[test]
fn screenshots_equal_render_across_conservative_renderers() {
    let Some(x) = Xvfb::start("screenshots_equal_render_across_conservative_renderers") else {
        return;
    };
    let dir = scratch("screenshots");
    let shot = |name: &str| s(&dir.join(name)).to_string();
    // The list is zbuffer, frustum, hzb, oqgrid, nbuffer, lzb, rzb: keys 2 and 3, then Tab.
    let script = format!(
        "view circle:8:3\nscreenshot {}\nkey 2\nwait-frame\nscreenshot {}\nkey 3\nscreenshot {}\nkey tab\nscreenshot {}\n\
         algo nbuffer\nscreenshot {}\nalgo lzb\nscreenshot {}\nalgo lzb:caster=octree,select=dynamic\nmode depth\nwait-frame\n\
         mode color\nscreenshot {}\nexit\n",
        shot("zbuffer.png"),
        shot("frustum.png"),
        shot("hzb.png"),
        shot("oqgrid.png"),
        shot("nbuffer.png"),
        shot("lzb.png"),
        shot("lzb-dynamic.png"),
    );
    let script_file = dir.join("script.txt");
    std::fs::write(&script_file, script).expect("the script is written");
    let out = x.view(&[CITY, "--algo", "zbuffer", "--size", SIZE, "--script", s(&script_file)]);
    assert_ok(&out, "occult view --script");
    let reference = render(&dir, CITY, "circle:8:3", "render.png");
    for name in ["zbuffer", "frustum", "hzb", "oqgrid", "nbuffer", "lzb", "lzb-dynamic"] {
        assert!(
            bytes(&dir.join(format!("{name}.png"))) == reference,
            "{name}'s screenshot differs from occult render's frame"
        );
    }
}

#[test]
fn a_recorded_path_replays_in_walk() {
    let Some(x) = Xvfb::start("a_recorded_path_replays_in_walk") else {
        return;
    };
    let dir = scratch("record");
    let path = dir.join("flown.json");
    let shot = |i: usize| s(&dir.join(format!("shot-{i}.png"))).to_string();
    let script = format!(
        "record start\nscreenshot {}\nmove forward 3\nscreenshot {}\nturn 15 -5\nscreenshot {}\nkey d\nkey d\n\
         screenshot {}\nrecord stop {}\nexit\n",
        shot(0),
        shot(1),
        shot(2),
        shot(3),
        s(&path)
    );
    let script_file = dir.join("script.txt");
    std::fs::write(&script_file, script).expect("the script is written");
    assert_ok(
        &x.view(&[
            TERRAIN,
            "--algo",
            "frustum",
            "--size",
            SIZE,
            "--script",
            s(&script_file),
        ]),
        "occult view --script",
    );
    // `key d` twice is two cameras: five in all, screenshots of the 1st, 2nd, 3rd and 5th.
    let frames = dir.join("frames");
    let replayed = dir.join("replayed.json");
    let stdout = assert_ok(
        &occult(&[
            "walk",
            "--scene",
            TERRAIN,
            "--path",
            s(&path),
            "--size",
            SIZE,
            "--algo",
            "zbuffer",
            "--frames-out",
            s(&frames),
            "--path-out",
            s(&replayed),
        ]),
        "occult walk",
    );
    assert!(stdout.contains("5 frames"), "{stdout}");
    let recorded: serde_json::Value = serde_json::from_slice(&bytes(&path)).expect("the recorded path is JSON");
    let read_back: serde_json::Value = serde_json::from_slice(&bytes(&replayed)).expect("walk's path is JSON");
    assert_eq!(recorded, read_back, "walk reads the cameras that were recorded");
    for (i, frame) in [(0, 0), (1, 1), (2, 2), (3, 4)] {
        assert!(
            bytes(&dir.join(format!("shot-{i}.png"))) == bytes(&frames.join(format!("frame_{frame:05}.png"))),
            "screenshot {i} differs from walk's frame {frame}"
        );
    }
}

#[test]
fn fly_reports_frame_rate_and_input_latency() {
    let Some(x) = Xvfb::start("fly_reports_frame_rate_and_input_latency") else {
        return;
    };
    let dir = scratch("fly");
    let script_file = dir.join("script.txt");
    let capture = dir.join("window.png");
    std::fs::write(
        &script_file,
        format!(
            "key h\ncapture {}\nkey h\nmode exactness\nwait-frame\nfly 10\nexit\n",
            s(&capture)
        ),
    )
    .expect("the script is written");
    let stdout = assert_ok(
        &x.view(&[TERRAIN, "--algo", "hzb", "--size", SIZE, "--script", s(&script_file)]),
        "occult view --script",
    );
    assert!(stdout.contains("input latency over"), "{stdout}");
    assert!(stdout.contains("frames per second"), "{stdout}");
    let png = bytes(&capture);
    assert_eq!(&png[1..4], b"PNG", "the capture is a PNG");
}

#[test]
fn exactness_mode_counts_no_differing_pixel_for_conservative_renderers() {
    let Some(x) = Xvfb::start("exactness_mode_counts_no_differing_pixel_for_conservative_renderers") else {
        return;
    };
    let dir = scratch("exactness");
    let json = |name: &str| dir.join(format!("{name}.json"));
    let mut script = String::from("view circle:8:5\nmode exactness\n");
    for algo in ["hzb", "oqgrid", "rzb"] {
        script.push_str(&format!("algo {algo}\nstats {}\n", s(&json(algo))));
    }
    script.push_str("exit\n");
    let script_file = dir.join("script.txt");
    std::fs::write(&script_file, script).expect("the script is written");
    assert_ok(
        &x.view(&[CITY, "--size", SIZE, "--script", s(&script_file)]),
        "occult view --script",
    );
    let read = |name: &str| -> serde_json::Value {
        serde_json::from_slice(&bytes(&json(name))).expect("the statistics are JSON")
    };
    for algo in ["hzb", "oqgrid"] {
        let stats = read(algo);
        assert_eq!(stats["renderer"], algo);
        assert_eq!(stats["mode"], "exactness");
        assert_eq!(stats["differing_pixels"], 0, "{algo}: {stats}");
        assert!(stats["triangles_visible"].as_u64().is_some_and(|v| v > 0), "{stats}");
    }
    assert!(read("rzb")["differing_pixels"].as_u64().is_some(), "rzb is checked too");
}

/// `rzb` on the forest of 1.4·10^14 triangles at 640×480: a frame of seconds on two cores,
/// which a camera move cancels; the frame after it is the new view's, as `occult render`
/// draws it, and the cancelled one is never shown.
#[test]
fn a_slow_frame_is_cancelled_by_moving_and_the_next_is_the_new_view() {
    let Some(x) = Xvfb::start("a_slow_frame_is_cancelled_by_moving_and_the_next_is_the_new_view") else {
        return;
    };
    const FOREST: &str = "forest:replicate=73,levels=2";
    const BIG: &str = "640x480";
    let dir = scratch("cancel");
    let shot = dir.join("moved.png");
    let stats = dir.join("moved.json");
    let during = dir.join("during.png");
    // `wait-progress`: the first view's frame is under way (drawing samples) when the camera
    // moves, so it is in flight, not merely pending, and is cancelled, not replaced. The
    // window is captured while it draws, its progress bar showing.
    let script = format!(
        "view circle:8:1\nwait-progress\nsleep 300\ncapture-now {}\nview circle:8:3\nscreenshot {}\nstats {}\nexit\n",
        s(&during),
        s(&shot),
        s(&stats)
    );
    let script_file = dir.join("script.txt");
    std::fs::write(&script_file, script).expect("the script is written");
    let stdout = assert_ok(
        &x.view(&[FOREST, "--algo", "rzb", "--size", BIG, "--script", s(&script_file)]),
        "occult view --script",
    );
    let cancelled: u64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("frames cancelled: "))
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("no count of cancelled frames: {stdout}"));
    assert!(cancelled >= 1, "the first view's frame was not cancelled: {stdout}");
    let json: serde_json::Value = serde_json::from_slice(&bytes(&stats)).expect("the statistics are JSON");
    assert_eq!(json["renderer"], "rzb", "{json}");
    // The bar along the bottom edge: filled (amber) from the left as far as the frame got.
    let window = image::open(&during).expect("the capture is a PNG").to_rgb8();
    let bottom = window.height() - 1;
    let amber = image::Rgb([0xff, 0xd0, 0x40]);
    assert_eq!(
        window.get_pixel(0, bottom),
        &amber,
        "no progress bar in the window while drawing"
    );

    let out = dir.join("render.png");
    assert_ok(
        &occult(&[
            "render",
            "--scene",
            FOREST,
            "--view",
            "circle:8:3",
            "--size",
            BIG,
            "--algo",
            "rzb",
            "--out",
            s(&out),
        ]),
        "occult render",
    );
    assert!(
        bytes(&shot) == bytes(&out),
        "the screenshot after the cancelled frame differs from occult render's frame of the new view"
    );
}

#[test]
fn no_display_is_one_line_naming_the_alternatives() {
    let out = Command::new(env!("CARGO_BIN_EXE_occult"))
        .args(["view", TERRAIN])
        .env_remove("DISPLAY")
        .output()
        .expect("the occult binary runs");
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    for needle in ["display", "occult render", "occult walk"] {
        assert!(stderr.contains(needle), "{needle}: {stderr}");
    }
}

#[test]
fn bad_scenes_and_scripts_fail_as_the_other_commands_do() {
    let dir = scratch("bad");
    let missing = s(&dir.join("no-such-model.obj")).to_string();
    let render = occult(&["render", "--scene", &missing, "--out", "x.png"]);
    let view = Command::new(env!("CARGO_BIN_EXE_occult"))
        .args(["view", &missing])
        .env_remove("DISPLAY")
        .output()
        .expect("the occult binary runs");
    assert_eq!(view.status.code(), render.status.code());
    // The same cause after the argument's name (`<SCENE>` here, `--scene <SPEC>` there).
    let cause = |o: &Output| text(&o.stderr).split("no-such-model.obj: ").last().map(str::to_string);
    assert_eq!(cause(&view), cause(&render), "{}", text(&view.stderr));

    let script = dir.join("bad.txt");
    std::fs::write(&script, "wait-frame\nfly sideways\n").expect("the script is written");
    let out = Command::new(env!("CARGO_BIN_EXE_occult"))
        .args(["view", TERRAIN, "--script", s(&script)])
        .env_remove("DISPLAY")
        .output()
        .expect("the occult binary runs");
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    assert!(stderr.contains("line 2") && stderr.contains("frame count"), "{stderr}");

    let Some(x) = Xvfb::start("bad_scenes_and_scripts_fail_as_the_other_commands_do") else {
        return;
    };
    let broken = dir.join("broken.obj");
    std::fs::write(&broken, "v 0 0 0\nv 1 0 0\nf 1 2 9\n").expect("the model is written");
    let render = occult(&["render", "--scene", s(&broken), "--out", s(&dir.join("x.png"))]);
    let view = x.view(&[s(&broken)]);
    assert!(!view.status.success());
    assert_eq!(text(&view.stderr), text(&render.stderr));
}
