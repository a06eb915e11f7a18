//! `occult shadows`: shadow volumes of a spot light counted in a stencil pass, with or without
//! culling and clamping by min/max litmaps and N-buffers (Décoret 2005 §3.3, §4.4), from one
//! view or along a camera path (§4.4 measured "along recorded path").

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use occult_core::{Camera, Vec3, View};
use occult_harness::shadows::{shadows, LightSettings, Modes, ShadowsConfig, ShadowsFrame};
use occult_raster::shade;
use serde::Serialize;

use crate::args::{
    parse_finite, parse_path, parse_scene, parse_size, parse_vec3, parse_view, CameraOverrides, PathArg, SceneArg,
    Size, ViewArg,
};
use crate::output;
use crate::scene::{self, SceneSummary};

/// `occult shadows`.
#[derive(Debug, Args)]
pub struct ShadowsArgs {
    /// Scene spec or file (see `occult render --help`).
    #[arg(long, value_name = "SPEC", value_parser = parse_scene)]
    pub scene: SceneArg,
    /// Camera: `default`, or camera `i` of a path as `PATH:i` (see `occult render --help`).
    #[arg(long, value_name = "VIEW", default_value = "default", conflicts_with = "path", value_parser = parse_view)]
    pub view: ViewArg,
    /// Camera path instead of one view (`circle:N`, `street:N`, `flyover:N` or a JSON file of
    /// cameras, as `walk` and `compare` take): per-frame and mean figures; the image is the
    /// last frame's.
    #[arg(long, value_name = "PATH", value_parser = parse_path)]
    pub path: Option<PathArg>,
    #[command(flatten)]
    pub camera: CameraOverrides,
    /// Frame size, WxH pixels.
    #[arg(long, value_name = "WxH", default_value = "640x480", value_parser = parse_size)]
    pub size: Size,
    /// Spot light position, `x,y,z`; default: above and beside the scene.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub light: Option<Vec3>,
    /// Point the light aims at, `x,y,z`; default: the scene's centre.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub light_target: Option<Vec3>,
    /// Full cone angle of the light, degrees, in (0, 170]; default: holds the whole scene.
    #[arg(long, value_name = "DEG", value_parser = parse_finite, allow_negative_numbers = true)]
    pub cone: Option<f32>,
    /// Litmap side in lexels.
    #[arg(long, value_name = "N", default_value_t = 512)]
    pub litmap: u32,
    /// Triangles per caster: larger meshes are split into the leaves of a BVH (>= 1).
    #[arg(long, value_name = "N", default_value_t = 4096)]
    pub leaf: usize,
    /// Clamp the shadow volumes (`on`), draw them whole (`off`), or both, checking that the
    /// shadows are identical (`both`).
    #[arg(long, value_name = "on|off|both", default_value = "both", value_parser = ["on", "off", "both"])]
    pub clamp: String,
    /// Shaded image darkened where in shadow (PNG).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Counts and timings out (JSON).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

#[derive(Serialize)]
struct ShadowsOut {
    scene: SceneSummary,
    /// The camera path, when given.
    path: Option<String>,
    /// The (last) camera.
    camera: Camera,
    width: u32,
    height: u32,
    light: [f32; 3],
    light_target: [f32; 3],
    cone_deg: f32,
    litmap: u32,
    casters: usize,
    /// Per clamping mode, the mean of every figure over the frames (the one frame's figures
    /// for a single view).
    runs: Vec<serde_json::Value>,
    /// With `--clamp both`: pixels whose shadow state differs, over all frames (always 0).
    differing_pixels: Option<u64>,
    /// Per frame.
    frames: Vec<ShadowsFrame>,
}

/// Runs the command.
pub fn run(a: ShadowsArgs) -> Result<()> {
    output::check_outputs([&Some(a.out.clone()), &a.json])?;
    if a.leaf == 0 {
        bail!("--leaf must be at least 1");
    }
    let config = ShadowsConfig {
        light: LightSettings {
            position: a.light,
            target: a.light_target,
            cone_deg: a.cone,
            resolution: a.litmap,
        },
        leaf: a.leaf,
        modes: match a.clamp.as_str() {
            "on" => Modes::Clamped,
            "off" => Modes::Unclamped,
            _ => Modes::Both,
        },
    };
    // The light's own checks on the values given, before the scene is built.
    config.light.check()?;
    a.camera.check()?;
    let scene = scene::load(&a.scene)?;
    let cameras = match &a.path {
        Some(p) => scene::path(p, &scene)?,
        None => vec![scene::camera(&a.view, &a.camera, &scene)?],
    };
    let views = cameras
        .iter()
        .enumerate()
        .map(|(i, c)| View::new(*c, a.size.width, a.size.height).with_context(|| format!("camera {i}")))
        .collect::<Result<Vec<_>>>()?;
    let report = shadows(&scene.scene, &views, &config)?;
    // Per clamping mode: the mean over the frames (the one frame's figures for one view).
    let means = report.means()?;
    let modes = means.len();
    let differing = report.differing_pixels();
    let (light, frames, caster_count) = (report.light, report.frames, report.caster_count);
    let (mut frame, last) = report.last;
    let view = views.last().expect("one camera at least");
    shade(&mut frame, &scene.scene, view);
    let mut img = frame.color_image();
    last.darken(&mut img);
    img.save_with_format(&a.out, image::ImageFormat::Png)
        .with_context(|| format!("cannot write '{}'", a.out.display()))?;

    let summary = scene.summary();
    say!(
        "scene {}: {} triangles, {} shadow casters (leaf {})",
        summary.label(),
        output::count(summary.triangles as f64),
        output::count(caster_count as f64),
        a.leaf
    );
    say!(
        "light at {:?} aimed at {:?}, cone {}°, litmaps {}x{}; frame {}x{}",
        light.position.to_array(),
        light.target.to_array(),
        light.cone_deg,
        a.litmap,
        a.litmap,
        a.size.width,
        a.size.height
    );
    let num = |v: &serde_json::Value, key: &str| v[key].as_f64().unwrap_or(0.0);
    if frames.len() > 1 {
        say!(
            "path {}: {} frames{}",
            a.path.as_ref().map_or("", |p| p.text.as_str()),
            frames.len(),
            if modes == 2 {
                "; per frame, unclamped → clamped"
            } else {
                ""
            }
        );
        for (i, f) in frames.iter().enumerate() {
            let r = f.runs.last().expect("one mode at least");
            let mut line = format!(
                "  frame {i:>3}: casters culled {} clamped {}; stencil fragments {}",
                output::count(r.casters_culled as f64),
                output::count(r.casters_clamped as f64),
                output::count(r.stencil_fragments as f64),
            );
            if let ([off, on], Some(d)) = (f.runs.as_slice(), f.differing_pixels) {
                line = format!(
                    "  frame {i:>3}: casters culled {} clamped {}; stencil fragments {} → {} ({:.1} %); {} → {} ms; identical {}",
                    output::count(on.casters_culled as f64),
                    output::count(on.casters_clamped as f64),
                    output::count(off.stencil_fragments as f64),
                    output::count(on.stencil_fragments as f64),
                    100.0 * on.stencil_fragments as f64 / off.stencil_fragments.max(1) as f64,
                    output::millis(off.total_ms),
                    output::millis(on.total_ms),
                    if d == 0 { "yes".to_string() } else { format!("NO ({d} pixels)") }
                );
            }
            say!("{line}");
        }
        say!("mean per frame:");
    }
    let header = [
        "clamping",
        "casters",
        "culled",
        "clamped",
        "lookups",
        "volume tris",
        "stencil frags",
        "shadowed px",
        "total ms",
        "stencil ms",
    ];
    let rows: Vec<Vec<String>> = means
        .iter()
        .map(|r| {
            let mut row = vec![if r["clamp"] == true { "on" } else { "off" }.to_string()];
            for key in [
                "casters",
                "casters_culled",
                "casters_clamped",
                "lookups",
                "volume_triangles",
                "stencil_fragments",
                "shadowed_pixels",
            ] {
                row.push(output::count(num(r, key)));
            }
            row.push(output::millis(num(r, "total_ms")));
            row.push(output::millis(num(r, "stencil_ms")));
            row
        })
        .collect();
    say_raw!("{}", output::table(&header, &rows));
    if let Some(d) = differing {
        let (off, on) = (&means[0], &means[1]);
        say!(
            "clamped fill {:.2} % of unclamped; time {:.2}x; shadows identical{}: {}",
            100.0 * num(on, "stencil_fragments") / num(off, "stencil_fragments").max(1.0),
            num(off, "total_ms") / num(on, "total_ms").max(1e-9),
            if frames.len() > 1 { " on every frame" } else { "" },
            if d == 0 {
                "yes".to_string()
            } else {
                format!("NO ({d} pixels differ)")
            }
        );
    }
    say!("wrote {}", a.out.display());
    if let Some(p) = &a.json {
        let out = ShadowsOut {
            scene: summary,
            path: a.path.as_ref().map(|p| p.text.clone()),
            camera: *cameras.last().expect("one camera at least"),
            width: a.size.width,
            height: a.size.height,
            light: light.position.to_array(),
            light_target: light.target.to_array(),
            cone_deg: light.cone_deg,
            litmap: a.litmap,
            casters: caster_count,
            runs: means,
            differing_pixels: differing,
            frames,
        };
        output::write_json(p, &out)?;
        say!("wrote {}", p.display());
    }
    if differing.is_some_and(|d| d > 0) {
        bail!("shadows differ with and without clamping");
    }
    Ok(())
}
